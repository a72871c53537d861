"""rclpy node modules of the driver package and helpers shared by every node (imports rclpy)."""
