"""The test run is isolated on this machine, and the ros_context fixture works."""

import os


def test_ros_environment_is_isolated():
    assert os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    assert 0 <= int(os.environ['ROS_DOMAIN_ID']) <= 232


def test_ros_context_uses_the_run_domain(ros_context):
    import rclpy

    node = rclpy.create_node('tskf_ros_env_check', context=ros_context)
    try:
        assert ros_context.ok()
        assert ros_context.get_domain_id() == int(os.environ['ROS_DOMAIN_ID'])
    finally:
        node.destroy_node()
