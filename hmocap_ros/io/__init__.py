"""Message <-> numpy conversion, bag reading/writing, record and replay (no rclpy here)."""
