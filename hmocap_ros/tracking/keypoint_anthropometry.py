"""Anthropometry from keypoints (thesis sec. 2.3, its entities measured instead of searched):
the body's bone scale factors from the distances between labelled 3D keypoints over the
first seconds of a track.

Per frame set, each measure of :data:`MEASURES` is a distance between keypoints of score at
least ``min_score`` (both sides averaged where both are seen): the shoulders' distance,
shoulder to elbow, elbow to wrist, hip to knee plus knee to ankle, knee to ankle, the hips'
distance, twice wrist to hand, ankle to foot, the hips' midpoint to the shoulders' midpoint,
the shoulders' midpoint to the head. A measure over a track is the median over its frames (a
wrong keypoint in a few frames does not move it), divided by its *correction*: the ratio of
the keypoint distance to the same distance between the body model's points
(:data:`~.keypoint_fit.MODEL_POINTS`, their landmark offsets included) of the subject:
what the offsets leave of the network's bias. The corrections ship with the body model
(``hmocap_ros/data/keypoint_model.json``), measured once on simulated clips that no
evaluation uses (``tools/learn_keypoint_model.py``).

The shape: the global scale ``g`` and the bone scale factors ``b`` of the entities that
minimise

    sum_m ((log M_m(g, b) - log s_m) / sigma)^2 + (log g / tau_g)^2
        + sum_e (log b_e / tau_e)^2

with ``M(g, b)`` the measures of the model's points in its rest pose on that shape, ``s_m``
the corrected measures, ``sigma`` = ``size_std`` (relative), ``tau_e`` the entity's prior
relative std (table 2.1) and ``tau_g`` the global scale's. Entities and the global scale
multiply bone lengths, so the log-distances are linear in the log-factors wherever a measure
spans the bones of one entity, and near linear for the others: one linear solve about the
model's proportions, then one more about that solution. The aggregates (``shoulder_height``,
``arms``) keep their factor 1, their parts carry the measures; the girths that keypoints do
not see (the radial factors) stay 1, scaled by the global scale like the rest.
"""
from __future__ import annotations

import numpy as np

from hmocap_ros.body.anthropometry import ENTITIES, ENTITY_NAMES, BodyShape, apply_shape

__all__ = ["MEASURES", "KeypointShape", "frame_measures", "model_log_measures",
           "size_corrections"]

#: measure (an entity of ENTITY_NAMES) -> the keypoint distances it averages
MEASURES = ("clavicles", "upperarms", "lowerarms", "legs", "lowerlegs", "hip_width", "hands",
            "feet", "torso", "head")
#: relative prior std of the aggregate entities' factors (held at 1)
_AGGREGATE_STD = 1e-3
#: relative prior std of the global scale (people's statures: about 4 % of the mean)
GLOBAL_PRIOR_STD = 0.05


def _mid(named, a, b):
    return 0.5 * (named[a] + named[b]) if a in named and b in named else None


def _dist(a, b):
    return float(np.linalg.norm(a - b)) if a is not None and b is not None else np.nan


def frame_measures(named: dict) -> np.ndarray:
    """(M,) the measures of :data:`MEASURES` of one frame set's keypoints ``{label: (3,)}``
    (NaN where a keypoint is missing), uncorrected."""
    def sides(fn):
        vals = [v for v in (fn("left"), fn("right")) if np.isfinite(v)]
        return float(np.mean(vals)) if vals else np.nan

    def d(a, b):
        return _dist(named.get(a), named.get(b))

    shoulders = _mid(named, "left_shoulder", "right_shoulder")
    hips = _mid(named, "left_hip", "right_hip")
    out = {
        "clavicles": d("left_shoulder", "right_shoulder"),
        "upperarms": sides(lambda s: d(f"{s}_shoulder", f"{s}_elbow")),
        "lowerarms": sides(lambda s: d(f"{s}_elbow", f"{s}_wrist")),
        "legs": sides(lambda s: d(f"{s}_hip", f"{s}_knee") + d(f"{s}_knee", f"{s}_ankle")),
        "lowerlegs": sides(lambda s: d(f"{s}_knee", f"{s}_ankle")),
        "hip_width": d("left_hip", "right_hip"),
        "hands": sides(lambda s: 2.0 * d(f"{s}_wrist", f"{s}_hand")),
        "feet": sides(lambda s: d(f"{s}_ankle", f"{s}_foot")),
        "torso": _dist(hips, shoulders),
        "head": _dist(shoulders, named.get("head")),
    }
    return np.array([out[m] for m in MEASURES])


def size_corrections(table: dict) -> np.ndarray:
    """(M,) the corrections of :data:`MEASURES` from ``{measure: ratio}`` (1 where absent)."""
    return np.array([float(table.get(m, 1.0)) for m in MEASURES])


def model_log_measures(model, fit, log_factors: np.ndarray) -> np.ndarray:
    """(M,) the log-measures of the model's points in its rest pose on the shape whose log
    bone factors (E) and log global scale are ``log_factors`` (E + 1,)."""
    n = len(ENTITY_NAMES)
    shape = BodyShape(np.exp(log_factors[:n]), np.ones(n), float(np.exp(log_factors[n])))
    points = fit.body_points(model.rest_pose(None)[None], apply_shape(model, shape))[0]
    return np.log(frame_measures(dict(zip(fit.labels, points))))


def _linearised(model, fit, about: np.ndarray, step: float = 0.02):
    """The log-measures at ``about`` (E + 1 log-factors) and their Jacobian (M, E + 1)."""
    base = model_log_measures(model, fit, about)
    jac = np.stack([(model_log_measures(model, fit, about + step * e) - base) / step
                    for e in np.eye(len(about))], axis=1)
    return base, jac


class KeypointShape:
    """The measures of a track's first frames and the shape they give (module docstring).

    model: the tracking body; corrections: (M,) per measure (:func:`size_corrections`);
    fit: the :class:`~.keypoint_fit.KeypointFit` whose body points the measures compare with
    (its landmark offsets); min_score: keypoints below it are not measured; size_std: sigma
    (relative).
    """

    def __init__(self, model, corrections: np.ndarray, fit=None, min_score: float = 0.5,
                 size_std: float = 0.03):
        from hmocap_ros.tracking.keypoint_fit import KeypointFit

        self.model = model
        self.fit = fit if fit is not None else KeypointFit(model)
        self.corrections = np.asarray(corrections, float)
        self.min_score = min_score
        self.size_std = size_std
        self.rows: list[np.ndarray] = []
        self._prior = np.array([_AGGREGATE_STD if not e.sampled else
                                (np.sqrt(e.prior_cm[1]) / e.prior_cm[0] if e.prior_cm
                                 else e.rel_std) for e in ENTITIES] + [GLOBAL_PRIOR_STD])

    def __len__(self) -> int:
        return len(self.rows)

    def add(self, detections) -> None:
        """Measure one frame set's keypoints (a Detections)."""
        named: dict[str, tuple[np.ndarray, float]] = {}
        for label, pos, score in zip(detections.labels, detections.positions, detections.scores):
            if score >= self.min_score and np.all(np.isfinite(pos)):
                if label not in named or score > named[label][1]:
                    named[label] = (np.asarray(pos, float), float(score))
        self.rows.append(frame_measures({k: v[0] for k, v in named.items()}))

    def measures(self) -> np.ndarray:
        """(M,) the corrected medians (NaN: never measured)."""
        if not self.rows:
            return np.full(len(MEASURES), np.nan)
        rows = np.array(self.rows)
        seen = np.isfinite(rows).any(axis=0)
        med = np.full(len(MEASURES), np.nan)
        med[seen] = np.nanmedian(rows[:, seen], axis=0)
        return med / self.corrections

    def shape(self) -> BodyShape | None:
        """The body shape of the measures so far (module docstring), or None before any."""
        measured = self.measures()
        have = np.isfinite(measured) & (measured > 0)
        if not have.any():
            return None
        fit = self.fit
        target = np.log(measured[have])
        x = np.zeros(len(ENTITY_NAMES) + 1)
        for about in (x, None):
            about = x if about is None else about
            base, jac = _linearised(self.model, fit, about)
            a = jac[have] / self.size_std
            r = (target - base[have]) / self.size_std + a @ about
            prior = np.diag(1.0 / self._prior)
            x = np.linalg.solve(a.T @ a + prior @ prior, a.T @ r)
        x = np.clip(x, np.log(0.7), np.log(1.4))
        n = len(ENTITY_NAMES)
        return BodyShape(np.exp(x[:n]), np.ones(n), float(np.exp(x[n])))
