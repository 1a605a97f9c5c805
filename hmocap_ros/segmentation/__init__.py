"""Foreground segmentation: per-pixel single-Gaussian background model with shadow removal
(thesis sec. 2.4, after Xu et al. [128]), mask clean-up, and mask scores against ground truth."""

from hmocap_ros.segmentation.background_model import BackgroundModel, compile_kernels
from hmocap_ros.segmentation.mask_metrics import MaskScores, mask_scores
from hmocap_ros.segmentation.params import ForegroundParams

__all__ = ["BackgroundModel", "ForegroundParams", "MaskScores", "compile_kernels", "mask_scores"]
