"""The layered particle filter (thesis sec. 2.2), independent of any body model.

- :mod:`.layered_filter`: the generic run (alg. 1), annealing (eq. 2.9, 2.10, alg. 2), the
  layered kernel covariance (alg. 3), layered systematic resampling (alg. 4) and the layered
  run (alg. 5); independent of any body model.
- :mod:`.kernels`: transition kernels ``kernel(particles, std, rng)`` and box limits.
"""
from hmocap_ros.lpf.kernels import Kernel, clip_to_bounds, gaussian_kernel, identity_kernel
from hmocap_ros.lpf.layered_filter import (
                                           Layer,
                                           LayerDiagnostics,
                                           LayeredFilter,
                                           LayeredRunResult,
                                           WeightFn,
                                           annealed_filter,
                                           annealed_weights,
                                           annealing_stds,
                                           beta_for_survival_rate,
                                           effective_sample_size,
                                           gpf_run,
                                           hierarchical_filter,
                                           layer_diffusion_stds,
                                           layered_resample,
                                           lpf_run,
                                           survival_rate,
                                           systematic_resample_indices,
                                           weighted_std,
)

__all__ = [
    "Kernel", "clip_to_bounds", "gaussian_kernel", "identity_kernel", "Layer",
    "LayerDiagnostics", "LayeredFilter", "LayeredRunResult", "WeightFn", "annealed_filter",
    "annealed_weights", "annealing_stds", "beta_for_survival_rate", "effective_sample_size",
    "gpf_run", "hierarchical_filter", "layer_diffusion_stds", "layered_resample", "lpf_run",
    "survival_rate", "systematic_resample_indices", "weighted_std",
]
