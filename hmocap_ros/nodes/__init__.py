"""Thin rclpy nodes: parameters, message conversion, calls into the algorithm modules."""
