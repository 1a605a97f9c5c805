"""The front ends of the ``hmocap`` tool: options, printed summaries and exit status around the
algorithm modules and the nodes.

Every ``hmocap`` subcommand of the product is a module here with ``add_arguments(parser)`` and
``main_from_args(ns)`` (``main_from_args(ns, ros_args)`` for those that start ROS: record,
replay, view, calibrate); :mod:`hmocap_ros.cli` lists them (:data:`~hmocap_ros.cli.COMMANDS`,
:data:`~hmocap_ros.cli.COMMAND_GROUPS`). The work is done elsewhere: ``eval/`` keeps the evaluations
(``evaluate``, ``evaluate_gestures``, ...), ``nodes/`` the Node classes and their ``main`` for
``ros2 run``, imported here only inside the function that runs them, so a command's module
imports no rclpy. ``hmocap sim``'s front ends are the simulator's (:mod:`hmocap_sim.commands`).

This is the layer above ``gestures/``, ``segmentation/``, ``eval/`` and ``nodes/``: it may
import them, they never import it.
"""
