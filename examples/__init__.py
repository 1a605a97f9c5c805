"""Example interaction apps on :mod:`hmocap_ros.client`, installed as the package ``hmocap_examples``.

``light_switch`` (a gesture near a place toggles a light) and ``presence`` (who is in which zone);
``scenes`` writes the bags they are shown and tested on. The library never imports them.
"""
