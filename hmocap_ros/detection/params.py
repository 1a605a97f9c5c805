"""Parameters of the extremity detectors' keypoint detector (frozen dataclasses with descriptions).

The fields carry a ``description`` in their metadata, so the ``extremity_detection`` node
declares them as ROS parameters without this module importing rclpy.
"""
from __future__ import annotations

from dataclasses import dataclass

from hmocap_ros.params import param

__all__ = ["KeypointParams"]


@dataclass(frozen=True)
class KeypointParams:
    """Tunables of :class:`~hmocap_ros.detection.keypoint_detector.KeypointDetector` and
    :func:`~hmocap_ros.detection.keypoint_triangulation.triangulate_views`."""

    box_margin: float = param(
        1.15, "Side of the upright crop about a foreground box (the crop when the pose detector "
              "finds nobody) over the box's longer side (>= 1).")
    previous_box_pad: float = param(
        0.25, "Growth of the previous skeleton's projected radius (its farthest keypoint from "
              "the hips' midpoint) for a view without a track (>= 0).")
    min_blob_fraction: float = param(
        0.002, "Smallest foreground, as a fraction of the mask's pixels, that counts as a "
               "person (a view with less is skipped; in [0, 1)).")
    min_detection_score: float = param(
        0.5, "Smallest score of the pose detector for a detection to place a view's first "
             "crop (in [0, 1]).")
    min_pose_score: float = param(
        0.5, "Smallest pose presence score of a view's network output for its landmarks to be "
             "used and to place the view's next crop (in [0, 1]).")
    min_visibility: float = param(
        0.1, "Smallest keypoint weight (landmark visibility x presence x pose score, reduced "
             "outside the silhouette) for a view to take part in a keypoint (in [0, 1]).")
    confident_visibility: float = param(
        0.5, "When at least min_views agreeing views have a weight of this or more (in [0, 1]), "
             "only they are triangulated.")
    mask_tolerance_px: float = param(
        8.0, "A keypoint farther than this from the view's foreground (full-image pixels, "
             ">= 0) is outside the silhouette.")
    outside_mask_weight: float = param(
        0.3, "Factor on the weight of a keypoint outside the silhouette (in [0, 1]; 0 drops it).")
    max_reprojection_px: float = param(
        12.0, "tau: a view agrees with a 3D keypoint when its landmark lies within this many "
              "pixels of the point's projection (> 0).")
    min_views: int = param(
        2, "Fewest agreeing views for a keypoint to be reported (>= 2).")
    min_score: float = param(
        0.3, "Keypoints with a lower confidence are not reported (in [0, 1]).")
    resolve_swaps: bool = param(
        True, "Rename the sides of a view whose left and right disagree with the other views.")
    swap_margin: float = param(
        0.5, "The sides of views are renamed only when the consensus gained exceeds this share "
             "of the renamed views' weight (>= 0).")
    views_per_set: int = param(
        2, "Views whose landmark network runs per frame set (at least 2; more with "
           "pose_rate_hz), in rotation (the oldest landmarks first); the other views' latest "
           "landmarks are carried to the set's stamp by the tracked skeleton's motion. 0: every "
           "view, every set.")
    pose_rate_hz: float = param(
        15.0, "When > 0 (and views_per_set > 0), more views per frame set than views_per_set "
              "when the measured cost leaves room: as many as fit 1/pose_rate_hz seconds per set. "
              "Depends on the machine's speed: 0 where runs must repeat bit for bit (hmocap track "
              "sets 0).")
    max_carry_ms: float = param(
        400.0, "Landmarks older than this (ms) are not carried to a later frame set (> 0).")
    max_people: int = param(
        1, "People the keypoint stage follows (>= 1). Above 1 every tracked body gets its own "
           "crop and landmark run per view (from the tracked skeletons fed back, by body id) and "
           "the pose detector looks for the people no body follows; set it to the tracker's "
           "max_people.")
    occluded_share: float = param(
        0.5, "With several people: a body's crop in a view is left out when the box of a nearer "
             "body's projected keypoints covers more than this share of its own (in (0, 1]).")
    new_person_tolerance: float = param(
        0.06, "With several people: two views' pose detections are one new person when their "
              "keypoints triangulate within this share of the image's longer side (> 0).")
    search_every: int = param(
        1, "With several people and fewer tracked than max_people: the pose detector looks for "
           "new people on every this many frame sets (>= 1).")
    threads: int = param(
        1, "LiteRT threads of the landmark network and the pose detector (>= 1): one, as the "
           "room's other stages run beside it; more only on a machine with cores to spare.")

    def __post_init__(self) -> None:
        checks = {
            "box_margin": self.box_margin >= 1.0, "previous_box_pad": self.previous_box_pad >= 0,
            "min_blob_fraction": 0 <= self.min_blob_fraction < 1,
            "min_detection_score": 0 <= self.min_detection_score <= 1,
            "min_pose_score": 0 <= self.min_pose_score <= 1,
            "min_visibility": 0 <= self.min_visibility <= 1,
            "confident_visibility": 0 <= self.confident_visibility <= 1,
            "mask_tolerance_px": self.mask_tolerance_px >= 0,
            "outside_mask_weight": 0 <= self.outside_mask_weight <= 1,
            "max_reprojection_px": self.max_reprojection_px > 0,
            "min_views": int(self.min_views) == self.min_views and self.min_views >= 2,
            "min_score": 0 <= self.min_score <= 1,
            "threads": int(self.threads) >= 1,
            "views_per_set": int(self.views_per_set) == self.views_per_set and self.views_per_set >= 0,
            "pose_rate_hz": self.pose_rate_hz >= 0, "max_carry_ms": self.max_carry_ms > 0,
            "swap_margin": self.swap_margin >= 0,
            "max_people": int(self.max_people) == self.max_people and self.max_people >= 1,
            "occluded_share": 0 < self.occluded_share <= 1,
            "new_person_tolerance": self.new_person_tolerance > 0,
            "search_every": int(self.search_every) == self.search_every and self.search_every >= 1,
        }
        bad = [name for name, ok in checks.items() if not ok]
        if bad:
            raise ValueError("KeypointParams: out of range: "
                             + ", ".join(f"{n}={getattr(self, n)!r}" for n in bad))
