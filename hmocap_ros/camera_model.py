"""The public names of :mod:`hmocap_ros.geometry` under this module name, which the gesture nodes
(``nodes/gesture_detection.py``, ``nodes/gesture_trainer.py``) import; other modules import
:mod:`hmocap_ros.geometry`."""

from hmocap_ros.geometry import *  # noqa: F401,F403 (the names of hmocap_ros.geometry.__all__)
from hmocap_ros.geometry import __all__  # noqa: F401
