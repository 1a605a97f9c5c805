"""Markerless body tracking (thesis ch. 2): the body tracker, its methods and its parts.

The generic layered particle filter it runs is :mod:`hmocap_ros.lpf`; this subpackage holds
what is specific to the human body: the silhouette weighting, the layer schedules, the
visual hull and start-up, anthropometry estimation, limb and IK proposals, and the extremity
detector of detector-driven tracking.
"""
