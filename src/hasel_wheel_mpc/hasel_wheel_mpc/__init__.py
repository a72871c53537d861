"""The HASEL wheel's observer, disturbance estimator, MPC and the control core (no rclpy
outside the ``*_node`` modules)."""
