"""A tracking method and an extremity detector added from outside the package: each is one
class and one registry entry (docs/development.md, "Adding a tracking method / an extremity
detector"), and the tracker and the pipeline run them by name.

The examples: ``sir``, the plain particle filter (thesis sec. 2.2.1: one weighting of the
whole body per frame, then resampling and the inter-frame kernel), and ``red-gloves``, a
detector of red gloves (the red pixels inside each view's foreground, fused on the carved
hull's oriented surface like the skin detector, eq. 2.16-2.18), whose unlabelled candidates
the tracker assigns to its own body (eq. 2.19). The scene: the tracking body in a pose, exact
silhouettes in the cameras of ``config/rig_example.yaml`` at 320x240, grey clothes and red
hands.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from hmocap_ros.body import rest_pose
from hmocap_ros.detection.detections import UNKNOWN, Detections
from hmocap_ros.detection.detectors import DETECTORS, carries_labels
from hmocap_ros.detection.extremity_pipeline import ExtremityDetectionParams, ExtremityPipeline
from hmocap_ros.detection.skin_extremities import SkinExtremityDetector, SkinExtremityParams
from hmocap_ros.geometry.projection import project_batch
from hmocap_ros.lpf.layered_filter import Layer, LayeredFilter
from hmocap_ros.params import from_flat
from hmocap_ros.render import render_silhouettes
from hmocap_ros.tracking.body_layers import BodySchedule
from hmocap_ros.tracking.body_tracker import BodyTracker, TrackerParams
from hmocap_ros.tracking.methods import METHODS, TrackingMethod
from hmocap_ros.tracking.methods.base import LayeredMethod
from hmocap_ros.tracking.people_tracker import PeopleTracker

STAMP0 = 1_700_000_000_000_000_000


# ----------------------------------------------------------------------------- the examples


@dataclass(frozen=True)
class PlainParticleFilter(LayeredMethod):
    """One weighting of the whole body per frame over the whole images (eq. 2.8)."""

    def schedule(self, skel, n_particles, n_layers, sigma0, kernel, *, survival_rate,
                 apf_alpha, refine_nu, sweeps) -> BodySchedule:
        final = Layer(survival_rate=survival_rate, n_particles=n_particles, kernel=kernel)
        return BodySchedule(self, LayeredFilter(layers=(), sigma0=sigma0, final=final),
                            ((),), (False,))


class RedGloveDetector:
    """Red pixels inside the foreground, fused on the hull's surface (settings:
    ``params.skin``); unlabelled candidates."""

    name = "red-gloves"
    description = "red gloves on the hull's oriented surface"
    labelled = False

    def __init__(self, cameras, params, model_path=None):
        self.fusion = SkinExtremityDetector(tuple(cameras), params.skin)

    def reset(self) -> None:
        pass

    def close(self) -> None:
        pass

    def detect(self, images, masks, previous=None) -> Detections:
        maps = [None if img is None or m is None else
                np.where((img[..., 0] > 200) & (img[..., 1] < 60) & (m > 0), 255, 0
                         ).astype(np.uint8) for img, m in zip(images, masks)]
        cand = self.fusion.detect(masks, maps, None)
        return Detections(self.name, (UNKNOWN,) * len(cand.positions), cand.positions,
                          cand.scores, cand.normals, cand.surface, cand.probability)


@pytest.fixture
def registered(monkeypatch):
    """The two examples registered, one line each (the registries are restored after)."""
    monkeypatch.setitem(METHODS, "sir", PlainParticleFilter("sir", "SIR", "one weighting of "
                                                            "the whole body", 1, 400))
    monkeypatch.setitem(DETECTORS, RedGloveDetector.name, RedGloveDetector)


# ----------------------------------------------------------------------------- the scene


def arms_out(model):
    """Standing, the left arm forward and bent, the right arm out to the side."""
    skel = model.skeleton
    p = rest_pose(skel).copy()
    p[:3] = (0.3, p[1], -0.2)
    for dof, value in (("root_yaw", 0.5), ("l_shoulder_flex", 1.2), ("l_elbow_flex", 0.9),
                       ("r_shoulder_abd", 1.3), ("r_elbow_flex", 0.3)):
        p[skel.dof_index(dof)] = value
    return p


def scene(model, rig, params):
    """Masks (M, H, W) 0/255 and RGB images (M, H, W, 3): grey body, red hands, black room."""
    verts, _ = model.pose(np.atleast_2d(params))
    uv, _ = project_batch(verts, *rig.arrays())
    h, w = rig[0].height, rig[0].width
    masks = render_silhouettes(uv, model.faces, h, w)[0] * np.uint8(255)
    hand_vertex = np.isin(model.vertex_part, [model.joint_index("l_wrist"),
                                              model.joint_index("r_wrist")])
    hands = render_silhouettes(uv, model.faces[hand_vertex[model.faces].all(axis=1)], h, w)[0]
    images = np.zeros(masks.shape + (3,), np.uint8)
    images[masks > 0] = 128
    images[hands > 0] = (230, 20, 20)
    return masks, images


# ----------------------------------------------------------------------------- the tests


def test_a_method_registered_in_one_line_tracks_by_its_name(model, rig, registered):
    params = arms_out(model)
    masks, _ = scene(model, rig, params)
    assert isinstance(METHODS["sir"], TrackingMethod)
    tracker = BodyTracker(model, rig, from_flat(TrackerParams, {
        "method": "sir", "startup.working_width": 160, "startup.min_foreground": 30,
        "startup.estimate_shape": False}), np.random.default_rng(0))
    assert tracker.schedule.method is METHODS["sir"] and tracker.schedule.n_weightings == 1
    assert tracker.schedule.evaluations_per_frame == 400 and tracker.driven is None
    truth = model.pose(params[None])[1][0]
    for f in range(3):
        res = tracker.update(list(masks), STAMP0 + f)
    assert res.state == "tracking"
    error = np.linalg.norm(res.joints - truth, axis=1)
    assert error[0] < 0.05 and error.mean() < 0.10, error
    with pytest.raises(ValueError, match="method must be one of"):
        TrackerParams(method="sir-2")


def test_a_detector_registered_in_one_line_drives_the_tracker(model, rig, registered):
    params = arms_out(model)
    masks, images = scene(model, rig, params)
    pipeline = ExtremityPipeline(rig.cameras, ExtremityDetectionParams(
        detector="red-gloves", skin=SkinExtremityParams(mask_scale=1.0, voxel=0.025)))
    assert isinstance(pipeline.detector, RedGloveDetector)
    detections = pipeline.detect(list(images), list(masks))
    assert detections.detector == "red-gloves" and not carries_labels(detections)
    hands = model.pose(params[None])[1][0][[model.joint_index("l_wrist"),
                                             model.joint_index("r_wrist")]]
    nearest = np.linalg.norm(detections.positions[:, None] - hands[None], axis=2).min(axis=0)
    assert len(detections) >= 2 and (nearest < 0.15).all(), nearest
    # dd-hpf takes them as candidates of every person's tracker (eq. 2.19)
    people = PeopleTracker(model, rig, from_flat(TrackerParams, {
        "method": "dd-hpf", "filter.particles": 100, "startup.working_width": 160,
        "startup.min_foreground": 30, "startup.estimate_shape": False}),
        np.random.default_rng(0), max_people=1)
    for f in range(3):
        res = people.update(list(masks), STAMP0 + f, detections)[0]
    assert res.state == "tracking" and res.extremities.found[[0, 1]].all()
    with pytest.raises(ValueError, match="detector must be one of"):
        ExtremityDetectionParams(detector="blue-gloves")
