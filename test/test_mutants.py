"""Mutation check (``make test-mutants``): deliberate breakages of the method, each of which
must make the accuracy tests that guard it fail.

Each mutant is a monkeypatch of the real code. A mutant's check runs its catching tests in a
pytest of their own with this module loaded as a plugin (``-p test_mutants``) and the mutant
named in ``HMOCAP_MUTANT``; the plugin applies the patch before any test runs, and
``mutant_site/sitecustomize.py`` applies it in every Python process the tests start (the nodes). The check
passes when every catching test fails. The table in ``docs/development.md`` lists the mutants
and the tests that catch them.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent
ENV = "HMOCAP_MUTANT"

#: the arm blocks of the hierarchical schedules (tracking.body_layers.BODY_BLOCKS)
ARM_BLOCKS = {"l_shoulder", "r_shoulder", "l_elbow", "r_elbow"}


def arm_weighting_off(mp: pytest.MonkeyPatch) -> None:
    """The arm layers of the hierarchical schedules weigh every particle alike."""
    from hmocap_ros.tracking import body_tracker

    real = body_tracker.layer_weight_fn

    def layer_weight_fn(fitness, model, schedule, *args, **kwargs):
        weight = real(fitness, model, schedule, *args, **kwargs)
        arms = {k for k, blocks in enumerate(schedule.layer_blocks) if ARM_BLOCKS & set(blocks)}

        def mutant(particles, layer):
            return np.zeros(len(particles)) if layer in arms else weight(particles, layer)

        return mutant

    mp.setattr(body_tracker, "layer_weight_fn", layer_weight_fn)


def tracker_ignores_images(mp: pytest.MonkeyPatch) -> None:
    """The tracker's weighting returns one constant cost, whatever the silhouettes."""
    from hmocap_ros.tracking import body_tracker

    def layer_weight_fn(*args, **kwargs):
        return lambda particles, layer: np.zeros(len(particles))

    mp.setattr(body_tracker, "layer_weight_fn", layer_weight_fn)


def foreground_ignores_images(mp: pytest.MonkeyPatch) -> None:
    """The background model answers an empty mask for every frame."""
    from hmocap_ros.segmentation.background_model import BackgroundModel

    real = BackgroundModel.apply

    def apply(self, rgb, stamp_ns):
        return np.zeros_like(real(self, rgb, stamp_ns))

    mp.setattr(BackgroundModel, "apply", apply)


def entity_scales_frozen(mp: pytest.MonkeyPatch) -> None:
    """The start-up estimates the global scale only: every per-entity factor stays 1."""
    from hmocap_ros.tracking.anthropometry_estimation import SHAPE_KEYS, AnthropometryEstimator

    real = AnthropometryEstimator._clip

    def _clip(self, x):
        x = real(self, x)
        g = self.n_pose + SHAPE_KEYS.index("global")
        scale = x[:, g].copy()
        x[:, self.n_pose:] = 1.0
        x[:, g] = scale
        return x

    mp.setattr(AnthropometryEstimator, "_clip", _clip)


def forest_votes_shuffled(mp: pytest.MonkeyPatch) -> None:
    """The gesture forest's votes moved at random among the pixels with depth."""
    from test_gesture_cli import shuffled_votes

    mp.setattr("hmocap_ros.gestures.detection.forest_grid_votes", shuffled_votes(1))


def shadow_suppression_off(mp: pytest.MonkeyPatch) -> None:
    """The background model's shadow test never runs, whatever the parameters say."""
    from hmocap_ros.segmentation import background_model

    real = background_model.classify_and_update
    shadow = 9  # the ``shadow`` flag among classify_and_update's arguments

    def classify_and_update(*args):
        args = list(args)
        args[shadow] = False
        return real(*args)

    mp.setattr(background_model, "classify_and_update", classify_and_update)


def detector_terms_ignored(mp: pytest.MonkeyPatch) -> None:
    """The detection terms of the layers ignored: kf-hpf's keypoint term and dd-hpf's
    refinement layer (eq. 2.20-2.21); kf-hpf filters its uncertain blocks on the silhouettes
    alone."""
    from hmocap_ros.tracking.detector_driven import DetectorDriven
    from hmocap_ros.tracking.keypoint_first import KeypointFirst

    mp.setattr(DetectorDriven, "layer_terms", lambda self, assigned, rest: None)
    mp.setattr(KeypointFirst, "terms",
               lambda self, schedule, *args: [None] * len(schedule.layer_blocks))


def keypoints_on_the_other_side(mp: pytest.MonkeyPatch) -> None:
    """Labelled keypoints attached to the model's points of the other side (``left_*`` on
    ``r_*``) in kf-hpf's fit and keypoint terms."""
    from hmocap_ros.tracking import keypoint_fit

    other = {"l": "r", "r": "l"}

    def swapped(name):
        return other[name[0]] + name[1:] if name[:2] in ("l_", "r_") else name

    mp.setattr(keypoint_fit, "MODEL_POINTS",
               {label: (spec[0], *map(swapped, spec[1:]))
                for label, spec in keypoint_fit.MODEL_POINTS.items()})


def keypoint_check_off(mp: pytest.MonkeyPatch) -> None:
    """kf-hpf keeps every keypoint, whatever the silhouettes show."""
    from hmocap_ros.tracking import keypoint_first

    mp.setattr(keypoint_first, "contradicted", lambda *args, **kwargs: [])


def landmark_undistortion_skipped(mp: pytest.MonkeyPatch) -> None:
    """The views' landmarks triangulated as they are, in the distorted image."""
    from hmocap_ros.geometry.pinhole_camera import PinholeCamera

    mp.setattr(PinholeCamera, "undistort_pixels", lambda self, pixels: np.asarray(pixels, float))


def bundle_adjustment_keeps_outliers(mp: pytest.MonkeyPatch) -> None:
    """The bundle adjustment never drops an observation, however far from its projection."""
    from hmocap_ros.calibration import bundle_adjustment

    real = bundle_adjustment.bundle_adjust

    def bundle_adjust(*args, **kwargs):
        kwargs["outlier_px"] = np.inf
        return real(*args, **kwargs)

    mp.setattr(bundle_adjustment, "bundle_adjust", bundle_adjust)
    mp.setattr("hmocap_ros.calibration.pipeline.bundle_adjust", bundle_adjust)


def startup_shape_estimation_off(mp: pytest.MonkeyPatch) -> None:
    """A new track keeps the model's proportions: kf-hpf measures no shape from its keypoints,
    and the silhouette start-up keeps them scaled to the hull, whatever
    ``startup.estimate_shape`` says."""
    import dataclasses

    from hmocap_ros.tracking import body_tracker, startup

    real = startup.StartUp.__init__

    def __init__(self, params, *args, **kwargs):
        params = dataclasses.replace(
            params, startup=dataclasses.replace(params.startup, estimate_shape=False))
        real(self, params, *args, **kwargs)

    mp.setattr(startup.StartUp, "__init__", __init__)
    mp.setattr(body_tracker.BodyTracker, "_measure_shape", lambda self, *args: False)


def threshold_ignores_rho(mp: pytest.MonkeyPatch) -> None:
    """The trainer's threshold is th- whatever rho says (th = th-, sec. 3.4.1)."""
    from hmocap_ros.gestures import trainer

    mp.setattr(trainer, "blend_threshold", lambda th_pos, th_neg, rho: th_neg)


def moving_average_one_minus_sigma(mp: pytest.MonkeyPatch) -> None:
    """The trainer's moving averages weigh the newest value by 1 - sigma instead of sigma."""
    from hmocap_ros.gestures import trainer

    def moving_average(previous, value, sigma):
        return float(value) if previous is None else (1.0 - sigma) * float(value) + sigma * previous

    mp.setattr(trainer, "moving_average", moving_average)


def negatives_at_random(mp: pytest.MonkeyPatch) -> None:
    """The trainer's negatives are drawn anywhere in the frame instead of where the forest
    fires (on-the-fly detection, sec. 3.3.2), as many as the count rule asks."""
    from hmocap_ros.gestures import trainer

    def hard_negative_pixels(density, grid_depth, depth_m, stride, counts, half_size_px_m, background, rng):
        return trainer.random_negative_pixels(depth_m, int(counts.sum()), background, rng)

    mp.setattr(trainer, "hard_negative_pixels", hard_negative_pixels)


def keypoint_scores_ignored(mp: pytest.MonkeyPatch) -> None:
    """kf-hpf's keypoint fit weighs every keypoint it keeps alike, whatever its score."""
    from hmocap_ros.tracking.keypoint_fit import KeypointFit

    real = KeypointFit.targets

    def targets(self, detections, drop=()):
        rows, positions, scores = real(self, detections, drop)
        return rows, positions, np.ones_like(scores)

    mp.setattr(KeypointFit, "targets", targets)


def landmark_offsets_dropped(mp: pytest.MonkeyPatch) -> None:
    """kf-hpf's fit puts the keypoints on the model's points themselves: the landmark
    offsets of keypoint_model.json are never applied."""
    from hmocap_ros.tracking.keypoint_fit import KeypointFit

    real = KeypointFit.__init__

    def __init__(self, model, min_score=0.3, room=None, offsets=None):
        real(self, model, min_score, room, None)

    mp.setattr(KeypointFit, "__init__", __init__)


def size_corrections_not_applied(mp: pytest.MonkeyPatch) -> None:
    """The keypoint anthropometry measures the keypoints' medians as they are, whatever the
    size corrections say."""
    from hmocap_ros.tracking.keypoint_anthropometry import KeypointShape

    real = KeypointShape.measures

    def measures(self):
        return real(self) * self.corrections

    mp.setattr(KeypointShape, "measures", measures)


def keypoint_term_uncapped(mp: pytest.MonkeyPatch) -> None:
    """kf-hpf's keypoint term counts each keypoint's whole distance: no cap."""
    from hmocap_ros.tracking import keypoint_first

    mp.setattr(keypoint_first, "CAP", np.inf)


def large_residuals_explained(mp: pytest.MonkeyPatch) -> None:
    """kf-hpf counts a confident keypoint as explaining its block however far the fit left
    it."""
    from hmocap_ros.tracking import keypoint_first

    mp.setattr(keypoint_first, "MAX_RESIDUAL", np.inf)


def nearest_hand_picks_the_farthest(mp: pytest.MonkeyPatch) -> None:
    """Which body made a gesture: the hand joint farthest from its point (within the distance)
    instead of the nearest."""
    import hmocap_ros.client as client
    from hmocap_ros.client import geometry, room_state
    from hmocap_ros.client.bodies import HAND_JOINTS

    def nearest_hand(bodies, point, max_distance):
        target = np.asarray(point, dtype=np.float64)
        found = [(body, side, float(np.linalg.norm(p - target)))
                 for body in bodies for side, (hand, _elbow) in HAND_JOINTS.items()
                 if (p := body.joint(hand)) is not None]
        found = [f for f in found if f[2] <= max_distance]
        return max(found, key=lambda f: f[2]) if found else None

    for module in (geometry, client, room_state):
        mp.setattr(module, "nearest_hand", nearest_hand)


def gesture_body_is_the_first_tracked(mp: pytest.MonkeyPatch) -> None:
    """The body said to have made a gesture is the first one tracked, wherever its hands are."""
    from hmocap_ros.client.room_state import RoomState

    mp.setattr(RoomState, "body_of",
               lambda self, gesture, max_distance=0.5: next(iter(self.bodies.values()), None))


def light_cooldown_on_the_wall_clock(mp: pytest.MonkeyPatch) -> None:
    """light_switch's cool-down counted on the wall clock (time.monotonic_ns) instead of the
    gestures' stamps."""
    import time

    from hmocap_examples import light_switch

    class WallClockHold(light_switch.OncePerHold):
        def __call__(self, stamp_ns):
            return super().__call__(time.monotonic_ns())

    mp.setattr(light_switch, "OncePerHold", WallClockHold)


def floor_offset_sign_flipped(mp: pytest.MonkeyPatch) -> None:
    """A calibration's floor offset (``--floor``) applied with the wrong sign: the floor ends up
    2 f above the room's y = 0 instead of on it."""
    from hmocap_ros.calibration import formats
    from hmocap_ros.calibration.formats import world_frame

    real = world_frame.calibration_to_rig

    def calibration_to_rig(calibration, *, floor=0.0, **kwargs):
        return real(calibration, floor=-floor, **kwargs)

    mp.setattr(world_frame, "calibration_to_rig", calibration_to_rig)
    mp.setattr(formats, "calibration_to_rig", calibration_to_rig)


def import_stamps_ignore_start(mp: pytest.MonkeyPatch) -> None:
    """The imported bag's stamps count from the first frame set imported, not from the videos'
    start: ``--start`` leaves them as without it."""
    from hmocap_ros.video_import.importer import BASE_STAMP_NS, ImportPlan

    mp.setattr(ImportPlan, "stamp_ns",
               lambda self, frame_set: BASE_STAMP_NS + int(round(frame_set * 1e9 / self.fps)))


def min_views_ignored(mp: pytest.MonkeyPatch) -> None:
    """``hmocap eval consistency --min-views`` ignored: the triangulation check keeps the points of
    3 views or more whatever it says (the report still names the value asked)."""
    from hmocap_ros.eval import consistency

    real = consistency.consistency_report

    def consistency_report(bag, motion, *, min_views=3, **kwargs):
        report = real(bag, motion, **kwargs)
        report["min_views"] = int(min_views)
        return report

    mp.setattr(consistency, "consistency_report", consistency_report)


def views_left_out_never_counted(mp: pytest.MonkeyPatch) -> None:
    """The keypoint detector leaves disagreeing views out but never counts them: its
    ``views_left_out`` (and the extremity node's diagnostics) stay empty."""
    from hmocap_ros.detection.keypoint_detector import KeypointDetector

    real = KeypointDetector.detect

    def detect(self, *args, **kwargs):
        counts = dict(self.views_left_out)
        result = real(self, *args, **kwargs)
        self.views_left_out.clear()
        self.views_left_out.update(counts)
        return result

    mp.setattr(KeypointDetector, "detect", detect)


def kf_hpf_publishes_its_prediction(mp: pytest.MonkeyPatch) -> None:
    """kf-hpf publishes its prediction without fitting: a tracked frame set's keypoint fit
    returns the predicted pose as it is, every keypoint explained (so no filter runs either);
    a new track still starts from its keypoints."""
    import dataclasses

    from hmocap_ros.tracking.keypoint_fit import KeypointFit

    real = KeypointFit.fit

    def fit(self, detections, rest, prior=None, periods=1.0, drop=()):
        result = real(self, detections, rest, prior, periods, drop)
        if prior is None or result is None:
            return result
        return dataclasses.replace(result, params=np.array(prior, float),
                                   residuals=np.zeros_like(result.residuals))

    mp.setattr(KeypointFit, "fit", fit)


def joint_states_from_the_previous_frame_set(mp: pytest.MonkeyPatch) -> None:
    """Each body's joint_states carries the pose of its previous frame set (under the stamp of
    the current one); the skeleton and the rest stay right."""
    from hmocap_ros.tracking import tracker_messages

    real = tracker_messages.TrackerMessages.pose
    previous: dict = {}

    def pose(self, k, stamp_ns, result, shape_model):
        out = real(self, k, stamp_ns, result, shape_model)
        before, previous[id(self), k] = previous.get((id(self), k)), result.params
        if before is not None:
            out[0] = (out[0][0], tracker_messages.make_joint_state(
                self.model.skeleton.dof_names, before, stamp_ns, self.frame_id,
                factory=self.factory))
        return out

    mp.setattr(tracker_messages.TrackerMessages, "pose", pose)


def keypoint_shape_not_estimated(mp: pytest.MonkeyPatch) -> None:
    """kf-hpf's shape from the keypoints is the model's proportions, whatever they measure."""
    from hmocap_ros.body import BodyShape
    from hmocap_ros.tracking.keypoint_anthropometry import KeypointShape

    mp.setattr(KeypointShape, "shape", lambda self: BodyShape.neutral())


def crop_never_refreshed(mp: pytest.MonkeyPatch) -> None:
    """Each view keeps the crop of its first landmarks: the track is never refreshed from the
    later frame sets' landmarks (nor dropped when they lose the person)."""
    from hmocap_ros.detection.keypoint_detector import KeypointDetector

    real = KeypointDetector._follow

    def _follow(self, v, camera, view):
        if self._tracks[v] is None:
            real(self, v, camera, view)

    mp.setattr(KeypointDetector, "_follow", _follow)


def pose_detector_never_run(mp: pytest.MonkeyPatch) -> None:
    """The pose detector finds nobody in any image: a view without a previous crop takes
    the foreground's box, or nothing without a mask."""
    from hmocap_ros.detection.pose_detector import PoseDetector

    mp.setattr(PoseDetector, "detect", lambda self, image, roi=None: [])


@dataclass(frozen=True)
class Mutant:
    apply: Callable[[pytest.MonkeyPatch], None]
    catching: tuple  # test node ids (relative to test/) that must fail under the mutant
    survives: str = ""  # why no test catches it today ("" when caught)


TRACKING = "test_body_tracking.py::"
MUTANTS = {
    "arm_weighting_off": Mutant(arm_weighting_off, (
        TRACKING + "test_tracker_follows_a_short_sequence[tracking]",)),
    "tracker_ignores_images": Mutant(tracker_ignores_images, (
        TRACKING + "test_tracker_follows_a_short_sequence[tracking]",
        TRACKING + "test_tracker_follows_a_short_sequence[tracking_coarse]",
        TRACKING + "test_tracker_survives_dropped_cameras_empty_frames_and_no_person",
        "test_detector_driven.py::test_dd_hpf_tracks_with_skin_detections_and_runs_without")),
    "foreground_ignores_images": Mutant(foreground_ignores_images, (
        "test_segmentation.py::test_moving_blob_f1_after_learning",
        "test_segmentation.py::test_foreground_beats_naive_differencing_with_shadows_and_light_changes")),
    "entity_scales_frozen": Mutant(entity_scales_frozen, (
        TRACKING + "test_anthropometry_estimation_beats_the_model_proportions",
        TRACKING + "test_anthropometry_estimation_beats_a_fit_of_the_stature_alone"),
        survives="the per-entity estimation does not yet beat a fit of the stature alone: "
                 "freezing it loses nothing the tests can see"),
    "forest_votes_shuffled": Mutant(forest_votes_shuffled, (
        "test_gesture_cli.py::test_shipped_forest_detects_gestures_on_the_demo_bag",)),
    "detector_terms_ignored": Mutant(detector_terms_ignored, (
        "test_keypoint_first.py::test_the_keypoints_place_a_forearm_the_silhouettes_lost",)),
    "keypoints_on_the_other_side": Mutant(keypoints_on_the_other_side, (
        "test_keypoint_first.py::test_fit_follows_noisy_keypoints_of_a_clip",
        "test_keypoint_first.py::test_the_keypoints_place_a_forearm_the_silhouettes_lost")),
    "keypoint_check_off": Mutant(keypoint_check_off, (
        "test_keypoint_first.py::test_the_silhouettes_drop_a_wrist_put_in_empty_space",)),
    "landmark_undistortion_skipped": Mutant(landmark_undistortion_skipped, (
        "test_keypoint_triangulation.py::"
        "test_landmarks_of_wide_angle_lenses_are_undistorted_before_triangulation",)),
    "bundle_adjustment_keeps_outliers": Mutant(bundle_adjustment_keeps_outliers, (
        "test_calibration.py::test_bundle_adjustment_drops_the_corners_far_from_their_projection",)),
    "startup_shape_estimation_off": Mutant(startup_shape_estimation_off, (
        "test_keypoint_first.py::"
        "test_the_tracker_measures_the_shape_of_a_new_track_from_its_keypoints",)),
    "threshold_ignores_rho": Mutant(threshold_ignores_rho, (
        "test_gesture_trainer.py::test_threshold_follows_the_scripted_densities",)),
    "moving_average_one_minus_sigma": Mutant(moving_average_one_minus_sigma, (
        "test_gesture_trainer.py::test_threshold_follows_the_scripted_densities",)),
    "negatives_at_random": Mutant(negatives_at_random, (
        "test_gesture_trainer.py::test_negatives_are_mined_where_the_forest_fires",)),
    "shadow_suppression_off": Mutant(shadow_suppression_off, (
        "test_segmentation.py::test_cast_shadow_is_not_foreground",
        "test_segmentation.py::test_foreground_beats_naive_differencing_with_shadows_and_light_changes")),
    "keypoint_scores_ignored": Mutant(keypoint_scores_ignored, (
        "test_keypoint_fit_properties.py::"
        "test_a_wrong_keypoint_pulls_the_fit_by_the_square_root_of_its_score",)),
    "landmark_offsets_dropped": Mutant(landmark_offsets_dropped, (
        "test_keypoint_fit_properties.py::"
        "test_landmark_offsets_fit_keypoints_made_apart_from_the_fit_to_the_right_joints",)),
    "size_corrections_not_applied": Mutant(size_corrections_not_applied, (
        "test_keypoint_fit_properties.py::"
        "test_the_measures_are_the_keypoints_medians_divided_by_the_size_corrections",
        "test_keypoint_fit_properties.py::"
        "test_size_corrections_that_model_the_keypoints_bias_give_the_true_shape")),
    "keypoint_term_uncapped": Mutant(keypoint_term_uncapped, (
        "test_keypoint_fit_properties.py::"
        "test_a_kept_wrong_keypoint_out_of_reach_moves_the_pose_no_more_than_a_missing_one",)),
    "large_residuals_explained": Mutant(large_residuals_explained, (
        "test_keypoint_fit_properties.py::"
        "test_a_keypoint_the_fit_cannot_reach_makes_its_block_uncertain",)),
    "nearest_hand_picks_the_farthest": Mutant(nearest_hand_picks_the_farthest, (
        "test_client.py::test_nearest_hand_is_the_nearer_of_two_bodies_hands_within_reach",
        "test_example_apps.py::test_light_switch_names_the_body_whose_hand_made_the_pause")),
    "gesture_body_is_the_first_tracked": Mutant(gesture_body_is_the_first_tracked, (
        "test_example_apps.py::test_light_switch_names_the_body_whose_hand_made_the_pause",)),
    "light_cooldown_on_the_wall_clock": Mutant(light_cooldown_on_the_wall_clock, (
        "test_example_apps.py::test_light_cooldown_counts_by_the_stamps_at_any_replay_rate",)),
    "floor_offset_sign_flipped": Mutant(floor_offset_sign_flipped, (
        "test_calibration_formats.py::test_floor_offset_puts_the_floor_at_room_y_zero",)),
    "import_stamps_ignore_start": Mutant(import_stamps_ignore_start, (
        "test_import_videos.py::test_stamps_are_the_frames_times_in_the_videos_from_their_start",)),
    "min_views_ignored": Mutant(min_views_ignored, (
        "test_consistency.py::test_triangulated_points_fall_as_min_views_rises",)),
    "views_left_out_never_counted": Mutant(views_left_out_never_counted, (
        "test_extremity_detection.py::"
        "test_a_knocked_camera_is_left_out_counted_and_reported_in_the_diagnostics",)),
    "kf_hpf_publishes_its_prediction": Mutant(kf_hpf_publishes_its_prediction, (
        "test_mocap_eval.py::test_eval_reports_json_and_plot_on_the_demo_bag",)),
    "joint_states_from_the_previous_frame_set": Mutant(joint_states_from_the_previous_frame_set, (
        "test_body_tracker_node.py::test_joint_states_with_input_stamps_and_bounded_error",)),
    "keypoint_shape_not_estimated": Mutant(keypoint_shape_not_estimated, (
        "test_body_tracker_node.py::test_joint_states_with_input_stamps_and_bounded_error",)),
    "crop_never_refreshed": Mutant(crop_never_refreshed, (
        "test_keypoint_network.py::test_each_views_crop_follows_a_walking_person",)),
    "pose_detector_never_run": Mutant(pose_detector_never_run, (
        "test_extremity_detection.py::test_views_without_a_crop_find_the_person_with_the_pose_detector",)),
}

_patch: pytest.MonkeyPatch | None = None


def apply_named_mutant() -> None:
    """Apply the mutant named in ``HMOCAP_MUTANT``, once per process (the pytest process and,
    through ``mutant_site/sitecustomize.py``, every Python process it starts)."""
    global _patch
    name = os.environ.get(ENV)
    if name and _patch is None:
        _patch = pytest.MonkeyPatch()
        MUTANTS[name].apply(_patch)


def pytest_configure(config) -> None:
    """Plugin hook (``-p test_mutants``): apply the mutant named in ``HMOCAP_MUTANT``."""
    apply_named_mutant()


def pytest_unconfigure(config) -> None:
    if _patch is not None:
        _patch.undo()


def run_under_mutant(name: str) -> tuple[set, str]:
    """Run the mutant's catching tests with the mutant applied: (failed node ids, output)."""
    env = {**os.environ, ENV: name,
           "PYTHONPATH": os.pathsep.join([str(HERE / "mutant_site"), str(HERE),
                                          os.environ.get("PYTHONPATH", "")])}
    ids = [str(HERE / node) for node in MUTANTS[name].catching]
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           "-p", "test_mutants", "-m", "", "-rfEX", *ids],
                          cwd=HERE.parent, env=env, capture_output=True, text=True, timeout=900)
    out = proc.stdout + proc.stderr
    # "FAILED test/<file>::<test>" (a strict expected failure that passes is one too)
    failed = {m.group(1) for m in re.finditer(r"^FAILED test/(\S+)", out, re.M)}
    return failed, out


def _params():
    for name, mutant in MUTANTS.items():
        marks = [pytest.mark.mutants]
        if mutant.survives:
            marks.append(pytest.mark.xfail(strict=True, reason=mutant.survives))
        yield pytest.param(name, marks=marks, id=name)


@pytest.mark.parametrize("name", list(_params()))
def test_mutant_is_caught(name):
    failed, out = run_under_mutant(name)
    assert "error" not in out.splitlines()[-1].lower(), out[-3000:]  # failures, not crashes
    missed = [node for node in MUTANTS[name].catching if node not in failed]
    assert not missed, f"{name} passes {missed}:\n{out[-3000:]}"
