"""Parameters of the foreground segmentation (one frozen dataclass, one set per camera).

The fields carry a ``description`` in their metadata, so the ``foreground_segmentation`` node
can declare them as ROS parameters (``hmocap_ros.nodes.common.declare_parameters``) without
this module importing rclpy. Defaults suit 640x480 colour cameras at 25 fps.
"""

from __future__ import annotations

from dataclasses import dataclass

from hmocap_ros.params import param


@dataclass(frozen=True)
class ForegroundParams:
    """Tunables of :class:`hmocap_ros.segmentation.BackgroundModel` (thesis sec. 2.4, after Xu et al. [128]).

    Colour values are in uint8 levels of the input image; rates are per frame.
    """

    learn_from: str = param(
        "empty_room", "Where the background is learnt: empty_room: from the first learn_frames "
                      "frames (after start or relearn), which must show the room empty, no "
                      "foreground before they are done; person_masks: each pixel from "
                      "learn_frames steady frames in which the landmark network's person "
                      "segmentation leaves it free, the network's mask standing in where a pixel "
                      "is not learnt yet (a person may be in view from the first frame).")
    learn_frames: int = param(
        25, "Frames (>= 1) that learn the background mean and variance: the first ones "
            "(empty_room: one second of an empty room at 25 fps), or per pixel the steady frames "
            "free of the person (person_masks).")
    k_sigma: float = param(
        3.5, "Foreground threshold: a pixel is foreground when its Mahalanobis distance to the "
             "background Gaussian (diagonal, 3 channels) exceeds k_sigma (standard deviations, > 0).")
    min_sigma: float = param(
        3.0, "Floor of every channel's standard deviation (levels, > 0, at most max_sigma): covers "
             "sensor noise that the learning frames under-sample and noise-free (rendered) images.")
    max_sigma: float = param(
        30.0, "Ceiling of every channel's standard deviation (levels, at least min_sigma), so that "
              "a flickering pixel does not become blind.")
    learning_rate: float = param(
        0.005, "Running-average rate of mean and variance where the pixel is background, per "
               "frame in [0, 1] (0.005 = 8 s time constant at 25 fps); 0 freezes the model.")
    absorb_frames: int = param(
        500, "A pixel that differs from the background for this many consecutive frames "
             "(0 to 65535; a moved chair, a new shadow) is absorbed into the background; 0 never "
             "absorbs.")
    absorb_rate: float = param(
        0.1, "Rate at which an absorbed pixel's mean moves to the new colour, per frame in (0, 1].")
    shadow_suppression: bool = param(
        True, "Label darker pixels of the background's chromaticity as shadow, not foreground.")
    shadow_min_brightness: float = param(
        0.5, "tau_low: the lowest brightness ratio (pixel / background, along the background colour; "
             "> 0 and below tau_high) that can still be a shadow; darker pixels are foreground.")
    shadow_max_brightness: float = param(
        1.0, "tau_high: shadows are strictly darker than this ratio of the background brightness "
             "(above tau_low, at most 1).")
    highlight_max_brightness: float = param(
        1.15, "Highest brightness ratio (pixel / gain-scaled background) at which a pixel of the "
             "background's chromaticity is still background: a surface lit by another source than "
             "the one that set the global gain (daylight through a window while a lamp dims); 1 "
             "or less disables it.")
    shadow_max_chroma: float = param(
        0.03, "Largest chromaticity distortion of a shadow or highlight: colour distance "
             "perpendicular to the background colour, divided by the pixel's brightness (tan of "
             "the colour angle, >= 0).")
    shadow_chroma_sigma: float = param(
        2.0, "Extra tolerance of the chromaticity test for sensor noise, in standard deviations "
             "(>= 0; matters for dark pixels, whose colour angle is noisy).")
    illumination_compensation: bool = param(
        True, "Estimate a global gain per frame (median brightness ratio over the last frame's "
              "background pixels) and compare each pixel with the gain-scaled background.")
    gain_sample_step: int = param(
        4, "Pixel step (rows and columns, >= 1) of the sample that estimates the global gain.")
    opening_size: int = param(
        3, "Side (pixels, >= 0) of the elliptic structuring element of the opening that removes "
           "speckle; 0 or 1 disables it.")
    closing_size: int = param(
        5, "Side (pixels, >= 0) of the elliptic structuring element of the closing that bridges "
           "small gaps; 0 or 1 disables it.")
    min_blob_area: int = param(
        100, "Connected foreground components smaller than this (pixels, >= 0) are removed; 0 keeps "
             "all.")
    max_hole_area: int = param(
        300, "Background holes inside a blob up to this area (pixels, >= 0) are filled; 0 fills none.")

    person_period: int = param(
        1, "person_masks: frames between two runs of the landmark network on a camera while it "
           "has pixels not learnt (>= 1; the last mask stands in between); the network stops "
           "once every pixel is learnt.")
    person_margin: float = param(
        0.02, "person_masks: growth of the person's mask, as a share of the image's height "
              "(>= 0; 10 pixels at 480), before it keeps pixels from being learnt.")
    person_threshold: float = param(
        0.5, "person_masks: the network's person probability (in (0, 1)) above which a pixel "
             "is the person.")

    def __post_init__(self):
        from hmocap_ros.segmentation import BACKGROUND_MODELS

        checks = [
            (self.learn_from in BACKGROUND_MODELS,
             f"learn_from must be one of {', '.join(BACKGROUND_MODELS)}, got {self.learn_from!r}"),
            (self.person_period >= 1, "person_period must be >= 1"),
            (self.person_margin >= 0, "person_margin must be >= 0"),
            (0.0 < self.person_threshold < 1.0, "person_threshold must be in (0, 1)"),
            (self.learn_frames >= 1, "learn_frames must be >= 1"),
            (self.k_sigma > 0.0, "k_sigma must be > 0"),
            (0.0 < self.min_sigma <= self.max_sigma, "need 0 < min_sigma <= max_sigma"),
            (0.0 <= self.learning_rate <= 1.0, "learning_rate must be in [0, 1]"),
            (0 <= self.absorb_frames <= 65535, "absorb_frames must be in [0, 65535]"),
            (0.0 < self.absorb_rate <= 1.0, "absorb_rate must be in (0, 1]"),
            (0.0 < self.shadow_min_brightness < self.shadow_max_brightness <= 1.0,
             "need 0 < shadow_min_brightness < shadow_max_brightness <= 1"),
            (self.shadow_max_chroma >= 0.0, "shadow_max_chroma must be >= 0"),
            (self.shadow_chroma_sigma >= 0.0, "shadow_chroma_sigma must be >= 0"),
            (self.gain_sample_step >= 1, "gain_sample_step must be >= 1"),
            (self.opening_size >= 0 and self.closing_size >= 0, "morphology sizes must be >= 0"),
            (self.min_blob_area >= 0 and self.max_hole_area >= 0, "areas must be >= 0"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(f"ForegroundParams: {message}")
