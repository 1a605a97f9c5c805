"""Export of a recorded body motion to files other tools read (docs/export.md).

``motion`` reads one body's skeleton, joint states and body shape from a bag into arrays
(tracker output or the simulator's ground truth); ``bvh_writer`` (Biovision hierarchy),
``trc`` (OpenSim markers) and ``csv_writer`` render them; ``formats`` is the registry the
``hmocap export`` command picks from; ``atomic_file`` writes a file whole or not at all.
No module here imports rclpy.
"""
