"""The ``hmocap sim`` front ends: options, the summary printed, exit status 2 with one line on
bad input. Each module has ``add_arguments(parser)`` and ``main_from_args(ns)``;
:data:`hmocap_ros.cli.COMMAND_GROUPS` names them by string, so the product imports the simulator
only when ``hmocap sim`` runs. The recordings themselves are the simulator's modules
(``generate`` in :mod:`hmocap_sim.mocap_dataset`, :mod:`hmocap_sim.gesture_dataset`,
:mod:`hmocap_sim.calibration_session`; the teacher's loop in
:mod:`hmocap_sim.nodes.simulated_teacher`).
"""
