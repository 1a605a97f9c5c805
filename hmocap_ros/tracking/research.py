"""Fresh searches while tracking: when to search again, and the search itself.

The per-frame filter only explores around its last estimate, so a wrong pose whose parts
make up for each other (a pelvis turned with the legs bent to compensate, legs swapped, a
body tracked back to front) is never left, although the silhouettes prefer the truth. A
fresh search runs the start-up's heading search and Powell fits (sec. 2.3.4) from the
visual hull of the person being tracked, at the estimated shape; when one of its poses has a
lower whole-body cost (eq. 2.8) than the filter's estimate, the filter is re-seeded from it.

:class:`ResearchPolicy` decides when (``research.*``): every ``every`` tracked frames; at
once when the pelvis travels and the body faces away from its travel (people walk and run
facing forward, and the silhouettes of a body seen from the front and from the back differ
little); and once as soon as the travel is first measured after a start. While the body
travels, a search also fits a pose facing the travel direction.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from hmocap_ros.tracking.anthropometry_estimation import AnthropometryEstimator
from hmocap_ros.tracking.limb_proposals import PROPOSAL_FRACTION
from hmocap_ros.tracking.params import EstimationParams, ResearchParams, TrackerParams
from hmocap_ros.tracking.startup import SAME_PERSON_RADIUS

__all__ = ["ResearchPolicy", "SearchDecision", "fresh_search"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SearchDecision:
    """A fresh search is due. reason: 'periodic', 'backwards' (the body faces away from its
    travel) or 'travel' (the first travel measured after a start); heading: the root yaw of
    the travel direction, searched in addition to the search's own headings, or None."""

    reason: str
    heading: float | None


class ResearchPolicy:
    """When a fresh search runs (see the module docstring)."""

    def __init__(self, params: ResearchParams):
        self.params = params
        self.reset()

    def reset(self, pelvis_track=()) -> None:
        """A new track; ``pelvis_track``: the (x, z) the pelvis is known to have travelled
        (the start-up's hull travel)."""
        self.tracked_frames = 0
        self.pelvis_track: list = list(pelvis_track)
        self.cooldown = 0
        self.travel_checked = False  # the first travel measured after a start searched once

    def _travel(self, pelvis_xz: np.ndarray) -> np.ndarray | None:
        """The pelvis travel (x, z) over the last ``backwards_frames`` frames, or None while
        off, not yet measured, or slower than ``backwards_step`` per frame. Records this
        frame's pelvis."""
        n = self.params.backwards_frames
        if n <= 0:
            return None
        self.pelvis_track.append(pelvis_xz.copy())
        del self.pelvis_track[:-(n + 1)]
        if len(self.pelvis_track) <= n:
            return None
        travel = self.pelvis_track[-1] - self.pelvis_track[0]
        if np.linalg.norm(travel) <= n * self.params.backwards_step:
            return None
        return travel

    def _facing_away(self, travel: np.ndarray | None, yaw: float) -> bool:
        """True when the pelvis travels and the facing direction (the root yaw: +Z turned
        towards +X) points more than ``facing_limit`` degrees away from it, outside the
        cool-down after a search."""
        if self.cooldown > 0:
            self.cooldown -= 1
            return False
        if travel is None:
            return False
        along = float(np.sin(yaw) * travel[0] + np.cos(yaw) * travel[1])
        if self.params.facing_limit == 90.0:
            return along < 0.0  # exactly (cos 90 degrees is 6e-17 in floating point)
        return along < np.cos(np.deg2rad(self.params.facing_limit)) * float(np.linalg.norm(travel))

    def after_frame(self, pelvis_xz: np.ndarray, yaw: float) -> SearchDecision | None:
        """Count one tracked frame with the estimate's pelvis (x, z) and root yaw; the search
        due now, or None."""
        self.tracked_frames += 1
        every = self.params.every
        travel = self._travel(pelvis_xz)
        backwards = self._facing_away(travel, yaw)
        first_travel = travel is not None and not self.travel_checked and self.cooldown == 0
        periodic = every > 0 and self.tracked_frames % every == 0
        if not (periodic or backwards or first_travel):
            return None
        heading = None
        if travel is not None:
            heading = float(np.arctan2(travel[0], travel[1]))
            self.travel_checked = True
        reason = "backwards" if backwards else "travel" if first_travel else "periodic"
        return SearchDecision(reason, heading)

    def searched(self) -> None:
        """A search ran: the pelvis track starts again, and the facing check waits
        ``every`` frames (at least ``backwards_frames``, which the track needs anyway)."""
        self.pelvis_track.clear()
        self.cooldown = max(self.params.every, self.params.backwards_frames)


def fresh_search(params: TrackerParams, fitness, finder, rng: np.random.Generator, room,
                 shape, proposer, obs, estimate: np.ndarray, previous: np.ndarray | None,
                 n_particles: int, stamp_ns: int, heading: float | None = None):
    """One fresh search on this frame (see the module docstring).

    Returns ``(estimate, particles, previous estimate)`` when a searched pose fits better
    than ``estimate``, else None. ``previous`` is moved with the estimate, so the velocity
    prediction of the next frame keeps this frame's step (a runner moves 12 cm a frame).
    """
    n = fitness.model.skeleton.n_dofs
    translation = fitness.model.skeleton.translation_dofs
    pelvis = estimate[translation]
    hull = finder.same_person(obs, pelvis)  # the person tracked, nobody else
    if hull is None or hull.top < params.hull.min_height:
        return None
    pf = PROPOSAL_FRACTION
    search = AnthropometryEstimator(
        fitness, EstimationParams(n_particles=params.startup.particles, frames=1,
                                  estimate_shape=False, proposal_fraction=pf),
        rng, room=room, fixed_shape=shape, proposer=proposer if pf > 0 else None)
    search.start(obs, hull, also=() if heading is None else (heading,))
    poses = np.stack([estimate] + [h.estimate[:n] for h in search.hypotheses])
    costs = fitness.costs(poses, obs, fitness.rest(shape))
    near = np.linalg.norm((poses[:, translation] - pelvis)[:, [0, 2]],
                          axis=1) <= SAME_PERSON_RADIUS
    costs = np.where(near, costs, np.inf)
    best = int(np.argmin(costs))
    if best == 0:
        return None
    log.info("stamp %d ns: a fresh search fits better (cost %.3f against %.3f): filter "
             "re-seeded", stamp_ns, costs[best], costs[0])
    particles = search.hypotheses[best - 1].particles[:, :n]
    idx = rng.choice(len(particles), size=n_particles, replace=len(particles) < n_particles)
    new_previous = None if previous is None else poses[best] - (estimate - previous)
    return poses[best].copy(), particles[idx].copy(), new_previous
