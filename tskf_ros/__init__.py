"""tskf_ros: two-stage Kalman filter (TSKF) core, ROS 2 nodes and experiments."""
