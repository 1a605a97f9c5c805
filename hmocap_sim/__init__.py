"""Synthetic smart room: body motion, cameras, rendering, MCAP bags with ground truth.

A package of its own beside :mod:`hmocap_ros`: it imports the product (body model, geometry,
bag writer, gesture classes, ChArUco board); the product never imports it (only the ``hmocap
sim`` front ends, when called).
"""

# hmocap_ros first: its __init__ pins numpy's BLAS to one thread before numpy loads (the
# numba kernels own the threads), so the simulator's renders repeat bit for bit.
import hmocap_ros  # noqa: F401 (imported for its side effect, above)
