"""tskf_ros: Kalman filtering on time scales (TSKF) for intermittent optical links, in ROS 2."""
