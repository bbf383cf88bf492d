"""Where ROS messages meet arrays: conversions, QoS, parameters and each node's interface."""
