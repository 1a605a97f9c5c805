"""The weighting function of a body schedule: eq. 2.8, eq. 2.15 in boxes, eq. 2.21.

:func:`layer_weight_fn` turns a :class:`~.body_layers.BodySchedule` and one frame's
observation into the ``weight_fn(particles, layer)`` of the layered filter
(:func:`hmocap_ros.lpf.layered_filter.lpf_run`): each layer skins and renders the particles
(:class:`~.body_fitness.SilhouetteFitness`) and counts the silhouette XOR over the whole
images (eq. 2.8) or inside the observation boxes of the layer's body parts (eq. 2.15,
:mod:`.observation_boxes`); with detections, the final layer adds the detection cost of
eq. 2.20 (the refinement layer, eq. 2.21) and each layer the distance of its joints to
their labelled detections (:mod:`.detector_driven`). :func:`fit_cost` is the cost the tracker judges a
frame's fit by.
"""
from __future__ import annotations

import time

import numpy as np

from hmocap_ros.render.silhouette import observed_counts
from hmocap_ros.tracking.body_fitness import Observation, serial_below
from hmocap_ros.tracking.observation_boxes import (
    BOX_MARGIN,
    BOX_REACH,
    BOX_SPREAD,
    LAYER_ANCHORS,
    chain_lengths,
    layer_boxes,
    layer_vertex_indices,
    part_boxes_3d,
    reach_box,
)

__all__ = ["fit_cost", "layer_vertices", "layer_weight_fn", "warm_up"]


def layer_vertices(model, schedule) -> list:
    """Per weighting of ``schedule``, the vertices of its boxed parts (None: not boxed)."""
    return [layer_vertex_indices(model, blocks) if boxed else None
            for blocks, boxed in zip(schedule.layer_blocks, schedule.boxed)]


def layer_weight_fn(fitness, model, schedule, vertices: list, obs: Observation, rest,
                    terms=None):
    """``weight_fn(particles, layer) -> costs`` of ``schedule`` on ``obs``.

    fitness: the :class:`~.body_fitness.SilhouetteFitness`; vertices: :func:`layer_vertices`;
    the boxes are :mod:`.observation_boxes`' (``BOX_*``); rest: the shaped rest body.
    terms: per weighting a ``cost_fn(particles, joints)`` added to its silhouette cost
    (detections, eq. 2.21) or None; or None.
    """
    lengths = chain_lengths(model, rest)

    def weight(particles: np.ndarray, layer: int) -> np.ndarray:
        verts, joints = fitness.pose(particles, rest)
        boxes = None
        if schedule.boxed[layer]:
            block = schedule.layer_blocks[layer][0]
            if block in LAYER_ANCHORS:
                anchor = joints[:, model.joint_index(LAYER_ANCHORS[block][0])]
                lo, hi = reach_box(anchor.mean(axis=0), lengths[block], BOX_REACH,
                                   BOX_MARGIN)
            else:
                lo, hi = part_boxes_3d(verts, vertices[layer], BOX_SPREAD, BOX_MARGIN)
            boxes = layer_boxes(lo, hi, obs.K, obs.R, obs.t, obs.D, obs.width, obs.height)
        cost = fitness.costs_from_verts(verts, obs, boxes)
        if terms is not None and terms[layer] is not None:
            cost = cost + terms[layer](particles, joints)
        return cost

    return weight


def fit_cost(fitness, estimate: np.ndarray | None, shape, obs: Observation) -> float:
    """Eq. 2.8 of ``estimate``, counted inside a box around its body (10 cm margin) and
    averaged over the views: a second person or a door elsewhere in the images does not make
    a good fit look collapsed. NaN without estimate or views."""
    if estimate is None or obs.n_views == 0:
        return float("nan")
    verts, _ = fitness.pose(estimate[None], shape)
    lo, hi = part_boxes_3d(verts, np.arange(verts.shape[1]), 0.0, 0.10)
    boxes = layer_boxes(lo, hi, obs.K, obs.R, obs.t, obs.D, obs.width, obs.height)
    with serial_below(obs.n_views):
        xor = fitness.view_xor_from_verts(verts, obs, boxes)[0]
    inside = observed_counts(obs.masks, boxes)
    return float(np.mean(xor / np.maximum(inside, fitness.min_count)))


def warm_up(fitness, proposer, model) -> float:
    """Compile every numba kernel of the weighting (serial and parallel variants) and of the
    limb proposals on a dummy frame; returns the seconds it took. A fresh install has no numba
    cache: without this, the first frames with a person would stall for seconds while they
    compile."""
    t0 = time.perf_counter()
    w = fitness.working[0]
    masks = [np.zeros((c.height, c.width), np.uint8) for c in fitness.working]
    obs = fitness.observe(masks)
    rest_params = model.rest_pose(None)[None]
    for n in (1, 128):  # serial and parallel paths
        params = np.repeat(rest_params, n, axis=0)
        fitness.costs(params, obs)
        verts, _ = fitness.pose(params)
        fitness.costs_from_verts(verts, obs, np.array([[0, 0, w.width, w.height]] * obs.n_views))
        fitness.costs_from_uv(fitness.project(verts, obs), obs)
    proposer.evidence(obs, rest_params[0], fitness.rest(None), fitness.faces)
    fitness.times.reset()
    return time.perf_counter() - t0
