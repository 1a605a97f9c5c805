"""hmocap_ros: markerless 3D body tracking and depth gesture localization for smart rooms (ROS 2 Jazzy)."""

import os as _os

# The hot paths are numba kernels with their own thread pool; numpy's BLAS calls here are
# small (shape bases, 3x3 algebra), so BLAS runs on one thread rather than competing with
# numba's (docs/development.md, "Costs the code is shaped by"). Takes effect when hmocap_ros is imported before
# numpy (every console script); set the variables yourself to choose otherwise.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    _os.environ.setdefault(_var, "1")

__version__ = "0.1.0"
