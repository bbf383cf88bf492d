"""ROS 2 nodes wrapping the TSKF core (the only place allowed to import rclpy)."""
