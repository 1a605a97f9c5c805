"""The simulator's rclpy nodes (a simulated user over DDS)."""
