"""REP-155 (ROS4HRI) outputs of the tracked bodies, built without rclpy (:mod:`.body_outputs`)."""
