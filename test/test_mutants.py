"""Mutation check (``make test-mutants``): deliberate breakages of the method, each of which
must make the accuracy tests that guard it fail.

Each mutant is a monkeypatch of the real code. A mutant's check runs its catching tests in a
pytest of their own with this module loaded as a plugin (``-p test_mutants``) and the mutant
named in ``HMOCAP_MUTANT``; the plugin applies the patch before any test runs. The check
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
}

_patch: pytest.MonkeyPatch | None = None


def pytest_configure(config) -> None:
    """Plugin hook (``-p test_mutants``): apply the mutant named in ``HMOCAP_MUTANT``."""
    global _patch
    name = os.environ.get(ENV)
    if name:
        _patch = pytest.MonkeyPatch()
        MUTANTS[name].apply(_patch)


def pytest_unconfigure(config) -> None:
    if _patch is not None:
        _patch.undo()


def run_under_mutant(name: str) -> tuple[set, str]:
    """Run the mutant's catching tests with the mutant applied: (failed node ids, output)."""
    env = {**os.environ, ENV: name,
           "PYTHONPATH": os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")])}
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
