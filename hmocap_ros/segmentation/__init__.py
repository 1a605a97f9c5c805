"""Foreground segmentation: per-pixel single-Gaussian background model with shadow removal
(thesis sec. 2.4, after Xu et al. [128]), learnt from an empty room or, without one, where the
landmark network's person masks say nobody is; mask clean-up, and mask scores against ground
truth.

:data:`BACKGROUND_MODELS` holds the two ways of learning the background (``learn_from``);
:func:`background_models` builds the one the parameters name for each camera.
"""

from hmocap_ros.segmentation.background_model import BackgroundModel, compile_background_kernels
from hmocap_ros.segmentation.mask_metrics import MaskScores, mask_scores
from hmocap_ros.segmentation.params import ForegroundParams
from hmocap_ros.segmentation.person_masked_background import PersonMaskedBackground, compile_learning

#: ``learn_from`` -> the model class of one camera.
BACKGROUND_MODELS = {"empty_room": BackgroundModel, "person_masks": PersonMaskedBackground}

__all__ = ["BACKGROUND_MODELS", "BackgroundModel", "ForegroundParams", "MaskScores",
           "PersonMaskedBackground", "background_models", "compile_kernels", "mask_scores"]


def compile_kernels(params: ForegroundParams | None = None) -> None:
    """Compile (or load from numba's cache) every kernel a segmenting model calls, now: those of
    :class:`BackgroundModel` with the argument types of ``params`` (defaults if None), then
    those of :class:`PersonMaskedBackground`. A node calls it before it subscribes, so that no
    kernel compiles on the first frames with a person."""
    compile_background_kernels(params)
    compile_learning()


def background_models(params: ForegroundParams | None, cameras) -> list:
    """One background model per camera of ``cameras`` (names), of the kind
    ``params.learn_from`` names; the person-mask models share one landmark network."""
    from hmocap_ros.segmentation.person_masks import PersonMasks

    params = params if params is not None else ForegroundParams()
    kind = BACKGROUND_MODELS[params.learn_from]
    if kind is PersonMaskedBackground:
        masks = PersonMasks()
        return [PersonMaskedBackground(params, masks, camera) for camera in cameras]
    return [kind(params) for _ in cameras]
