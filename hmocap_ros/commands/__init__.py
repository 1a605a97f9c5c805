"""Command glue of the ``hmocap`` tool: argument parsing, bag reading and reports around the
algorithm modules.

This is the layer above ``gestures/``, ``segmentation/`` and ``eval/``: it may import them,
they never import it. Each command module has ``add_arguments(parser)`` and
``main_from_args(ns)`` (:data:`hmocap_ros.cli.COMMAND_GROUPS`).

- :mod:`~hmocap_ros.commands.train_gestures`: ``hmocap train gestures``.
- :mod:`~hmocap_ros.commands.repair`: ``hmocap repair``.
"""
