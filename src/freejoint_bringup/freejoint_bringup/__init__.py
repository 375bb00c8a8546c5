"""freejoint_bringup: the graph's nodes in one process (composition for rclpy)."""
