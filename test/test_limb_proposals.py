"""Silhouette-driven limb proposals and the fused projection + XOR kernel of the tracker.

Scenes with known ground truth: the tracking body in a chosen pose, exact silhouettes in the
cameras of ``config/rig_example.yaml`` at 320x240 (working resolution 160x120).
"""
from __future__ import annotations

import numpy as np
import pytest

from hmocap_ros.body import rest_pose, sample_pose
from hmocap_ros.geometry.projection import project_batch
from hmocap_ros.render import render_silhouettes, xor_counts
from hmocap_ros.render.fused_xor import xor_counts_from_vertices
from hmocap_ros.tracking.body_fitness import SilhouetteFitness
from hmocap_ros.tracking.limb_proposals import LIMBS, LimbProposer


def cams(rig):
    return rig.arrays()


def masks_of(model, rig, params):
    verts, _ = model.pose(np.atleast_2d(params))
    uv, _ = project_batch(verts, *cams(rig))
    return render_silhouettes(uv, model.faces, rig[0].height, rig[0].width)[0] * np.uint8(255)


def standing(model, heading=0.5):
    p = rest_pose(model.skeleton).copy()
    p[:3] = (0.3, p[1], -0.2)
    p[model.skeleton.dof_index("root_yaw")] = heading
    return p


def test_fused_xor_equals_projection_then_xor(model, rig):
    rng = np.random.default_rng(1)
    params = sample_pose(model.skeleton, rng, 40)
    params[:, :3] = (0.2, 0.9, 0.1)
    verts, _ = model.pose(params)
    K, R, t, D = cams(rig)
    uv, _ = project_batch(verts, K, R, t, D)
    observed = render_silhouettes(uv[:4], model.faces, rig[0].height, rig[0].width)[np.arange(4), np.arange(4)]
    boxes = np.array([[30.0, 20.0, 250.0, 200.0]] * 4)
    for bx in (None, boxes):
        for front in (False, True):
            want = xor_counts(uv, model.faces, observed, bx, front_only=front)
            got = xor_counts_from_vertices(verts.astype(np.float32), K, R, t, D, model.faces,
                                           observed, bx, front_only=front)
            np.testing.assert_array_equal(got, want)
    assert want[:4][np.arange(4), np.arange(4)].tolist() == [0, 0, 0, 0]  # a pose vs itself
    with pytest.raises(ValueError):
        xor_counts_from_vertices(verts[:, :5], K, R, t, D, model.faces, observed)


def test_proposals_find_an_arm_the_reference_lost(model, rig):
    skel = model.skeleton
    truth = standing(model)
    arm = LIMBS["l_arm"]
    truth[skel.dof_index("l_shoulder_abd")] = np.deg2rad(80.0)   # arm out to the side ...
    truth[skel.dof_index("l_shoulder_flex")] = np.deg2rad(30.0)  # ... and a bit forward
    truth[skel.dof_index("l_elbow_flex")] = np.deg2rad(10.0)
    masks = masks_of(model, rig, truth)
    fitness = SilhouetteFitness(model, rig, working_scale=0.5)
    obs = fitness.observe(list(masks))
    reference = truth.copy()
    dofs = [skel.dof_index(n) for n in arm[0] + arm[1]]
    reference[dofs] = 0.0  # the reference has the arm down at rest
    rest = fitness.rest(None)
    proposer = LimbProposer(model, ("l_arm",))
    support, residual = proposer.evidence(obs, reference, rest, fitness.faces)
    assert residual.sum() > 0  # the raised arm is foreground the reference leaves unexplained
    values, costs = proposer.candidates("l_arm", reference, rest, obs, support, residual,
                                        np.random.default_rng(0),
                                        cost_fn=lambda x: fitness.costs(x, obs, rest))
    assert np.all(np.diff(costs) >= 0)  # cheapest first
    best = reference.copy()
    best[proposer.dofs("l_arm")] = values[0]
    c_true, c_ref, c_best = fitness.costs(np.stack([truth, reference, best]), obs, rest)
    assert c_best - c_true < 0.5 * (c_ref - c_true)  # most of the way (resampling keeps c_true > 0)
    # the proposed hand lies near the true one
    _, j_true = model.pose(truth[None])
    _, j_best = model.pose(best[None])
    wrist = model.joint_index("l_wrist")
    assert np.linalg.norm(j_true[0, wrist] - j_best[0, wrist]) < 0.12
    # apply(): the chosen fraction of particles gets proposals, the others are untouched
    particles = np.repeat(reference[None], 400, axis=0)
    proposer.apply(particles, reference, rest, obs, fitness.faces, 0.25,
                   np.random.default_rng(1), cost_fn=lambda x: fitness.costs(x, obs, rest))
    changed = np.any(particles != reference, axis=1)
    assert 0.15 < changed.mean() < 0.35
    assert np.all(particles[:, [i for i in range(skel.n_dofs) if i not in dofs]]
                  == reference[[i for i in range(skel.n_dofs) if i not in dofs]])


def test_proposals_are_seeded_and_reject_unknown_limbs(model, rig):
    truth = standing(model)
    masks = masks_of(model, rig, truth)
    fitness = SilhouetteFitness(model, rig, working_scale=0.5)
    obs = fitness.observe(list(masks))
    rest = fitness.rest(None)
    proposer = LimbProposer(model)
    support, residual = proposer.evidence(obs, truth, rest, fitness.faces)
    assert residual.sum() < 10  # the reference explains everything but resampling specks
    a = proposer.candidates("r_arm", truth, rest, obs, support, residual, np.random.default_rng(5))
    b = proposer.candidates("r_arm", truth, rest, obs, support, residual, np.random.default_rng(5))
    np.testing.assert_array_equal(a[0], b[0])
    with pytest.raises(ValueError):
        LimbProposer(model, ("tail",))
