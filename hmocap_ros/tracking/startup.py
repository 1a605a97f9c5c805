"""Finding the person and starting a track: visual hull, pose and anthropometry (sec. 2.3).

:class:`HullFinder` carves the visual hull of the person to follow (sec. 2.3.4) at the
tracker's settings and tells whether a hull is the person already followed.
:class:`StartUp` is one start-up: the layered anthropometry estimation of
:mod:`.anthropometry_estimation` over ``startup.frames`` frame sets (or one frame, pose only,
when the shape is given or known), its hypotheses moved along with the hull's centroid, and
at the end the first particles of the tracking filter.
"""
from __future__ import annotations

import logging

import numpy as np

from hmocap_ros.body.anthropometry import BodyShape
from hmocap_ros.detection.visual_hull import visual_hull
from hmocap_ros.tracking.anthropometry_estimation import AnthropometryEstimator
from hmocap_ros.tracking.body_fitness import Observation
from hmocap_ros.tracking.body_layers import SURVIVAL_RATE
from hmocap_ros.tracking.limb_proposals import PROPOSAL_FRACTION
from hmocap_ros.tracking.observation_boxes import layer_boxes
from hmocap_ros.tracking.params import EstimationParams, TrackerParams

__all__ = ["SAME_PERSON_RADIUS", "HullFinder", "StartUp"]

log = logging.getLogger(__name__)

#: How far (m, on the floor) the tracked person's hull (start-up) or a fresh search's pose
#: may lie from where the person was; farther is somebody else.
SAME_PERSON_RADIUS = 0.5
#: During the start-up frames: when the followed visual hull's top stands more than
#: HEIGHT_MARGIN (m) above the top of a start-up hypothesis' body, both read in a column of
#: radius HEIGHT_COLUMN (m) over its head (so that a hand raised beside the head tops
#: neither), its global scale and pelvis height grow by their ratio: the segmentation can
#: lose the head in the frame a track starts on, and the thesis' estimation (sec. 2.3) would
#: keep the shrunken body.
HEIGHT_MARGIN, HEIGHT_COLUMN = 0.03, 0.15


class HullFinder:
    """The visual hull of a person at the tracker's settings (``hull.*``, ``startup.*``)."""

    def __init__(self, params: TrackerParams, room):
        self.params = params
        self.room = room

    def hull(self, obs: Observation, near: np.ndarray | None = None, region=None,
             exclude: np.ndarray | None = None):
        """The visual hull of the person (sec. 2.3.4) nearest ``near`` (or the best seen)."""
        h, s = self.params.hull, self.params.startup
        return visual_hull(obs.masks, obs.K, obs.R, obs.t, obs.D, self.room,
                           fine_voxel=h.voxel_size, min_views=min(s.min_views, obs.n_views),
                           max_misses=h.max_misses, near=near, region=region,
                           exclude=exclude, exclude_radius=SAME_PERSON_RADIUS,
                           bridge_misses=h.bridge_misses)

    def same_person(self, obs: Observation, point: np.ndarray):
        """The hull of the person at ``point`` (room, 3), or None when the hull nearest it
        lies farther than :data:`SAME_PERSON_RADIUS` on the floor (``visual_hull``'s
        ``near`` falls back to the best-seen person, who may be somebody else)."""
        hull = self.hull(obs, near=point)
        if hull is None or np.linalg.norm((hull.centroid - point)[[0, 2]]) > SAME_PERSON_RADIUS:
            return None
        return hull

    @staticmethod
    def views_seeing_whole(hull, obs: Observation, margin_px: float = 1.0) -> int:
        """Number of views whose image holds the whole hull (its box's 8 corners)."""
        half = 0.5 * hull.voxel_size
        boxes = layer_boxes(hull.points.min(axis=0) - half, hull.points.max(axis=0) + half,
                            obs.K, obs.R, obs.t, obs.D, obs.width, obs.height, pad_px=0.0)
        inside = ((boxes[:, 0] >= margin_px) & (boxes[:, 1] >= margin_px)
                  & (boxes[:, 2] <= obs.width - margin_px) & (boxes[:, 3] <= obs.height - margin_px))
        return int(inside.sum())

    def person_to_start(self, obs: Observation, near: np.ndarray | None,
                        exclude: np.ndarray | None):
        """The hull of a person a track may start on, or None: tall enough, in the track
        region, away from the people in ``exclude``, and wholly inside enough views."""
        p = self.params
        hull = self.hull(obs, near=near, region=p.startup.track_region or None, exclude=exclude)
        if hull is None or hull.top < p.hull.min_height:
            return None
        if self.views_seeing_whole(hull, obs) < min(p.startup.min_full_views, obs.n_views):
            return None
        return hull


class StartUp:
    """One start-up (sec. 2.3): the anthropometry estimator and the hull it follows.

    fitness: the start-up's weighting (at ``startup.working_width``); shape: a known shape
    (pose-only start); proposer: limb proposals for the heading search, or None.
    """

    def __init__(self, params: TrackerParams, fitness, rng: np.random.Generator, room,
                 shape: BodyShape | None, proposer, obs: Observation, hull):
        s = params.startup
        self.params = params
        self.centroid = hull.centroid.copy()
        self.step = np.zeros(3)
        self.track: list = [hull.centroid[[0, 2]].copy()]  # the hull centroid's (x, z)
        est_params = EstimationParams(
            n_particles=s.particles,
            frames=s.frames if (s.estimate_shape and shape is None) else 1,
            estimate_shape=s.estimate_shape, survival_rate=SURVIVAL_RATE,
            proposal_fraction=PROPOSAL_FRACTION)
        self.estimator = AnthropometryEstimator(fitness, est_params, rng, room=room,
                                                fixed_shape=shape,
                                                proposer=proposer if PROPOSAL_FRACTION > 0
                                                else None)
        self.estimator.start(obs, hull)

    def first_estimate(self, fitness, obs: Observation, shape: BodyShape | None) -> np.ndarray:
        """The pose of the hypothesis that fits ``obs`` best (eq. 2.8), (D,)."""
        n = fitness.model.skeleton.n_dofs
        best = min(self.estimator.hypotheses,
                   key=lambda h: float(fitness.costs(h.estimate[None, :n], obs, shape)[0]))
        return best.estimate[:n].copy()

    def follow(self, obs: Observation, finder: HullFinder, translation_dofs) -> None:
        """Move the hypotheses with the visual hull's centroid (a runner crosses a metre
        during a four-frame start-up, far beyond the start-up's diffusion), and grow them
        to the hull's height (:data:`HEIGHT_MARGIN`)."""
        hull = finder.same_person(obs, self.centroid)
        if hull is None:
            self.step = np.zeros(3)
            self.track = []  # a gap: no travel measured across it
            return
        step = np.zeros(3)
        step[[0, 2]] = (hull.centroid - self.centroid)[[0, 2]]
        self.centroid = hull.centroid.copy()
        self.step = step
        self.track.append(hull.centroid[[0, 2]].copy())
        for hyp in self.estimator.hypotheses:
            hyp.particles[:, translation_dofs] += step
            hyp.estimate[translation_dofs] += step
        grown = self.estimator.grow_to(hull, HEIGHT_MARGIN, HEIGHT_COLUMN)
        if any(f != 1.0 for f in grown):
            log.info("start-up: the visual hull's top stands above the body (over its head; "
                     "the whole hull's top %.2f m); scale x %s",
                     hull.top, ", ".join(f"{f:.3f}" for f in grown))

    def finish(self, n_particles: int, rng: np.random.Generator, skel):
        """The first tracked frame's state: ``(estimate, particles, previous estimate,
        pelvis track)``. The hull's last step seeds the pelvis velocity, and the hull's
        travel during the start-up stands for the pelvis' (moved to end at the estimate),
        so that the fresh-search policy can judge the start-up's heading at once."""
        estimate = self.estimator.best().estimate[:skel.n_dofs].copy()
        pose = self.estimator.pose_particles()
        idx = rng.choice(len(pose), size=n_particles, replace=len(pose) < n_particles)
        particles = pose[idx]
        previous = estimate.copy()
        previous[skel.translation_dofs] -= self.step
        pelvis = estimate[skel.translation_dofs][[0, 2]]
        track = [c - self.track[-1] + pelvis for c in self.track] if self.track else []
        return estimate, particles, previous, track
