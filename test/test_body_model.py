"""Body model: shipped assets, skeleton parameterisation, FK/LBS (eq. 2.11-2.12), anthropometry.

Fast (a few seconds): no downloads, the reference values are copied in below.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import trimesh

from hmocap_ros.body import (
    ENTITY_NAMES,
    TABLE_2_1,
    BodyShape,
    apply_shape,
    entity_sizes,
    forward_kinematics,
    load_body_model,
    local_rotations_to_pose,
    pose_to_local_rotations,
    read_body_model,
    rest_pose,
    sample_pose,
    sample_shape,
    shape_log_prior,
    skin_vertices,
    skinning_matrices,
)
from hmocap_ros.body.rotations import axis_angle_matrix
from hmocap_ros.geometry.rotations import rotvec_to_matrix

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "hmocap_ros" / "data"

# body_model_reference.npz in the project's shared data folder (a reduction of the same CC0
# data): joint and end-site names, rest positions (m), height and volume, copied in.
REF_JOINT_NAMES = ("pelvis", "spine", "chest", "neck", "head", "l_clavicle", "l_shoulder",
                   "l_elbow", "l_wrist", "r_clavicle", "r_shoulder", "r_elbow", "r_wrist",
                   "l_hip", "l_knee", "l_ankle", "r_hip", "r_knee", "r_ankle")
REF_PARENTS = (-1, 0, 1, 2, 3, 2, 5, 6, 7, 2, 9, 10, 11, 0, 13, 14, 0, 16, 17)
REF_JOINTS = np.array([
    [0.0, 0.88944, 0.0], [0.0, 0.93544, -0.02408], [0.0, 1.24961, -0.02158],
    [0.0, 1.40578, -0.00764], [0.0, 1.51426, 0.00162], [0.02656, 1.3359, 0.05498],
    [0.16771, 1.34134, 0.00016], [0.31294, 1.16608, -0.00125], [0.43118, 1.06194, 0.1612],
    [-0.02656, 1.3359, 0.05498], [-0.16771, 1.34134, 0.00016], [-0.31294, 1.16608, -0.00125],
    [-0.43118, 1.06194, 0.1612], [0.11036, 0.86538, -0.00216], [0.15812, 0.44728, 0.01758],
    [0.21962, 0.07198, -0.01536], [-0.11036, 0.86538, -0.00216], [-0.15812, 0.44728, 0.01758],
    [-0.21962, 0.07198, -0.01536]])
REF_END_NAMES = ("head_top", "l_hand_tip", "r_hand_tip", "l_toe", "r_toe")
REF_END_SITES = np.array([
    [0.0, 1.6572, -0.0062], [0.47841, 0.94704, 0.28702], [-0.47841, 0.94704, 0.28702],
    [0.23086, 0.01651, 0.12086], [-0.23086, 0.01651, 0.12086]])
REF_HEIGHT = 1.666
REF_VOLUME = 0.0544  # m^3


@pytest.fixture(scope="module")
def tracking():
    return load_body_model("tracking")


@pytest.fixture(scope="module")
def hands():
    return load_body_model("hands")


@pytest.fixture(params=["tracking", "tracking_coarse", "hands"])
def model(request):
    return load_body_model(request.param)


def rng_for(seed: int) -> np.random.Generator:
    return np.random.default_rng(seed)


# --------------------------------------------------------------------------- assets
def test_asset_files_small_and_complete():
    for name in ("body_tracking.npz", "body_tracking_coarse.npz", "body_hands.npz"):
        path = DATA / name
        assert path.stat().st_size < 1.5e6
        with np.load(path, allow_pickle=False) as z:
            for key in ("vertices", "faces", "joint_names", "parents", "joints_rest", "weights",
                        "vertex_part", "end_site_names", "end_site_parents", "end_sites_rest",
                        "meta", "joint_source_bones", "joint_to_cmu_bvh"):
                assert key in z.files, (name, key)
    text = (DATA / "BODY_MODEL_SOURCES.md").read_text()
    assert "CC0" in text and "bad70bdc2be0dfa9880d60129c3a1339678f08f493184f637dc2825c3e27b8d2" in text


def test_triangle_counts_and_provenance(tracking, hands):
    coarse = load_body_model("tracking_coarse")
    assert 2000 <= len(tracking.faces) <= 2400
    assert len(coarse.faces) == 1000
    assert 8000 <= len(hands.faces) <= 15000
    for m in (tracking, coarse, hands):
        assert m.meta["wheel"]["version"] == "0.6.2"
        assert "CC0" in m.meta["license"]
        assert m.meta["decimated"]["watertight"]


def test_coarse_tracking_mesh_is_the_same_body(tracking):
    """The tracker's optional coarse mesh: 1,000 triangles on the joints, end sites,
    landmarks and DoFs of the 2,400-triangle body, and at the working resolution (160x120)
    the same silhouette up to a sliver along its outline."""
    from hmocap_ros.geometry.projection import project_batch
    from hmocap_ros.geometry.rig import camera_arrays, load_rig
    from hmocap_ros.render import render_silhouettes

    coarse = tracking.with_mesh("tracking_coarse")
    assert coarse.name == "tracking_coarse" and len(coarse.faces) == 1000
    assert coarse.joint_names == tracking.joint_names
    np.testing.assert_array_equal(coarse.joints_rest, tracking.joints_rest)
    np.testing.assert_array_equal(coarse.end_sites_rest, tracking.end_sites_rest)
    np.testing.assert_array_equal(coarse.end_site_parents, tracking.end_site_parents)
    assert coarse.landmarks.keys() == tracking.landmarks.keys()
    assert coarse.skeleton.dof_names == tracking.skeleton.dof_names
    assert tracking.with_mesh("tracking") is tracking
    with pytest.raises(ValueError, match="another skeleton"):
        tracking.with_mesh("hands")
    with pytest.raises(ValueError, match="unknown body model"):
        tracking.with_mesh("nope")

    params = sample_pose(tracking.skeleton, rng_for(3), 6, scale=0.7,
                         root_translation=(0.2, 0.9, -0.1))
    cams = [c.scaled(0.25) for c in load_rig(ROOT / "config" / "rig_example.yaml")]
    K, R, t, D = camera_arrays(cams)
    masks = []
    for m in (tracking, coarse):
        uv, _ = project_batch(m.pose(params)[0], K, R, t, D)
        masks.append(render_silhouettes(uv, m.faces, cams[0].height, cams[0].width,
                                        front_only=True).astype(bool))
    fine_px = masks[0].sum(axis=(2, 3))
    differ = (masks[0] ^ masks[1]).sum(axis=(2, 3))
    assert fine_px.min() > 150  # the person is in every view
    assert np.all(differ <= 0.08 * fine_px), differ / fine_px


def test_rest_mesh_watertight_single_component(model):
    mesh = trimesh.Trimesh(model.vertices, model.faces, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.euler_number == 2
    assert mesh.volume == pytest.approx(REF_VOLUME, rel=0.03)  # outward normals


def test_frame_and_height(model):
    v = model.vertices
    assert model.height == pytest.approx(REF_HEIGHT, abs=0.01)
    assert abs(v[:, 1].min()) < 0.005  # feet on the floor
    assert abs(v[:, 0].min() + v[:, 0].max()) < 0.005  # left/right symmetric about x = 0
    assert model.landmarks["l_index_knuckle"][0] > 0  # +X is the person's left
    toe = model.end_sites_rest[list(model.end_site_names).index("l_toe")]
    ankle = model.joints_rest[model.joint_index("l_ankle")]
    assert toe[2] > ankle[2] + 0.05  # facing +Z


def test_rest_joints_inside_bounding_box(model):
    lo, hi = model.vertices.min(0), model.vertices.max(0)
    assert np.all(model.joints_rest >= lo) and np.all(model.joints_rest <= hi)
    assert np.all(model.end_sites_rest >= lo - 0.01) and np.all(model.end_sites_rest <= hi + 0.01)


def test_weights_rows_sum_to_one(model):
    w = model.weights
    assert w.shape == (model.n_vertices, model.n_joints)
    assert np.all(w >= 0)
    np.testing.assert_allclose(w.sum(1), 1.0, atol=1e-5)
    part = model.vertex_part
    assert np.array_equal(part, np.argmax(w, axis=1))
    body = [model.joint_index(n) for n in REF_JOINT_NAMES]
    assert set(body) <= set(np.unique(part))  # every body joint owns some vertices


def test_matches_reference_skeleton(tracking, hands):
    assert tracking.joint_names == REF_JOINT_NAMES
    assert tuple(tracking.parents) == REF_PARENTS
    assert tracking.end_site_names == REF_END_NAMES
    np.testing.assert_allclose(tracking.joints_rest, REF_JOINTS, atol=0.01)
    np.testing.assert_allclose(tracking.end_sites_rest, REF_END_SITES, atol=0.01)
    # the hands model shares the body joints and frame
    np.testing.assert_allclose(hands.joints_rest[:19], tracking.joints_rest, atol=1e-6)
    assert hands.joint_names[:19] == REF_JOINT_NAMES
    assert hands.n_joints == 19 + 2 * 15


def test_corrupt_file_gives_clear_error(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip file")
    with pytest.raises(ValueError):
        read_body_model(bad)
    partial = tmp_path / "partial.npz"
    np.savez(partial, vertices=np.zeros((3, 3), np.float32))
    with pytest.raises(ValueError, match="missing keys"):
        read_body_model(partial)


def test_deterministic_npz_writer(tmp_path, load_tool):
    mod = load_tool("build_body_model")
    arrays = {"a": np.arange(5, dtype=np.float32), "names": np.array(["x", "yy"])}
    mod.write_npz_deterministic(tmp_path / "1.npz", arrays)
    mod.write_npz_deterministic(tmp_path / "2.npz", arrays)
    assert (tmp_path / "1.npz").read_bytes() == (tmp_path / "2.npz").read_bytes()
    with np.load(tmp_path / "1.npz") as z:
        assert list(z["names"]) == ["x", "yy"] and z["a"][4] == 4


# --------------------------------------------------------------------------- skeleton
def test_dof_set(tracking, hands):
    sk = tracking.skeleton
    assert 25 <= sk.n_dofs <= 30
    assert len(set(sk.dof_names)) == sk.n_dofs
    assert all(re.fullmatch(r"[a-z][a-z0-9_]*", n) for n in sk.dof_names)
    assert sk.dof_names[:6] == ("root_tx", "root_ty", "root_tz", "root_yaw", "root_pitch", "root_roll")
    assert np.all(sk.lower < 0) and np.all(sk.upper > 0)  # the rest pose is inside the limits
    for g in ("torso", "l_leg", "r_leg", "l_shoulder", "r_shoulder", "l_elbow", "r_elbow"):
        assert len(sk.group_dofs(g)) > 0
    full = hands.skeleton
    assert {"l_index1_flex", "l_thumb1_abd", "r_pinky3_flex", "l_wrist_flex"} <= set(full.dof_names)
    assert len(set(full.dof_names)) == full.n_dofs


@pytest.mark.parametrize("name,dofs", [("tracking", "tracking"), ("tracking", "full"),
                                       ("hands", "full")])
def test_pose_rotation_roundtrip(name, dofs):
    sk = load_body_model(name, dofs).skeleton
    params = sample_pose(sk, rng_for(1), 500)
    rot, root_t = pose_to_local_rotations(sk, params)
    np.testing.assert_allclose(rot @ np.swapaxes(rot, -1, -2), np.broadcast_to(np.eye(3), rot.shape),
                               atol=1e-12)
    back = local_rotations_to_pose(sk, rot, root_t)
    np.testing.assert_allclose(back, params, atol=1e-9)


def test_projection_of_foreign_rotations(tracking):
    sk = tracking.skeleton
    rng = rng_for(2)
    params = sample_pose(sk, rng, 200, scale=0.5)
    rot, root_t = pose_to_local_rotations(sk, params)
    # small rotations the parameterisation cannot express (e.g. forearm twist)
    noise = rotvec_to_matrix(rng.normal(scale=0.02, size=rot.shape[:2] + (3,)))
    proj = local_rotations_to_pose(sk, rot @ noise, root_t)
    assert np.all(proj >= sk.lower - 1e-12) and np.all(proj <= sk.upper + 1e-12)
    assert np.abs(proj - params).max() < 0.1
    # arbitrary rotations still map inside the limits
    wild = rotvec_to_matrix(rng.normal(scale=2.0, size=(50, sk.n_joints, 3)))
    proj = local_rotations_to_pose(sk, wild, np.zeros(3))
    assert np.all(np.isfinite(proj))
    wrap = np.zeros(sk.n_dofs, bool)
    wrap[sk.wrap_dofs] = True
    assert np.all(proj[:, ~wrap] >= sk.lower[~wrap] - 1e-12)
    assert np.all(proj[:, ~wrap] <= sk.upper[~wrap] + 1e-12)


def test_hinge_projection_is_least_squares():
    from hmocap_ros.body.rotations import hinge_angle

    axis = np.array([0.6, 0.0, 0.8])
    r = axis_angle_matrix(axis, 0.7) @ axis_angle_matrix(np.array([0.0, 1.0, 0.0]), 0.3)
    t = hinge_angle(r, axis)
    grid = np.linspace(-np.pi, np.pi, 20001)
    score = np.einsum("gij,ij->g", axis_angle_matrix(axis, grid), r)
    assert t == pytest.approx(grid[np.argmax(score)], abs=1e-3)


def _pose(model, **deg):
    p = model.rest_pose()
    for k, v in deg.items():
        p[model.skeleton.dof_index(k)] = np.deg2rad(v)
    return p


def test_dof_semantics(tracking):
    m = tracking
    jx = m.joint_index

    def joints(**deg):
        return m.pose(_pose(m, **deg))[1]

    rest = m.joints_rest
    j = joints(l_shoulder_flex=90)  # arm forward
    assert j[jx("l_elbow"), 2] - j[jx("l_shoulder"), 2] > 0.2
    j = joints(l_shoulder_abd=50)  # A-pose -> T-pose
    assert abs(j[jx("l_elbow"), 1] - j[jx("l_shoulder"), 1]) < 0.05
    assert j[jx("l_elbow"), 0] - j[jx("l_shoulder"), 0] > 0.2
    j = joints(l_elbow_flex=60)  # flexion brings the wrist towards the shoulder
    assert (np.linalg.norm(j[jx("l_wrist")] - j[jx("l_shoulder")])
            < np.linalg.norm(rest[jx("l_wrist")] - rest[jx("l_shoulder")]) - 0.05)
    j = joints(r_hip_flex=90)  # thigh forward
    assert j[jx("r_knee"), 2] - j[jx("r_hip"), 2] > 0.3
    j = joints(l_knee_flex=90)  # shank backward
    assert j[jx("l_ankle"), 2] - j[jx("l_knee"), 2] < -0.3
    j = joints(l_hip_abd=30)
    assert j[jx("l_knee"), 0] > rest[jx("l_knee"), 0] + 0.1
    j = joints(spine_flex=45)  # bend forward
    assert j[jx("neck"), 2] > 0.2
    j = joints(spine_bend=30)  # bend to the left (+X)
    assert j[jx("neck"), 0] > 0.1
    j = joints(root_yaw=90)  # turn left: the face points to +X
    toe = m.forward(_pose(m, root_yaw=90)).end_sites[0, list(m.end_site_names).index("l_toe")]
    assert toe[0] > j[jx("l_ankle"), 0] + 0.05
    j = joints(l_ankle_flex=20)  # dorsiflexion lifts the toes
    toe = m.forward(_pose(m, l_ankle_flex=20)).end_sites[0, list(m.end_site_names).index("l_toe")]
    assert toe[1] > REF_END_SITES[3, 1] + 0.02


def test_finger_semantics(hands):
    m = hands
    curl = {f"r_{f}{s}_flex": 80 for f in ("index", "middle", "ring", "pinky") for s in (1, 2, 3)}
    res = m.forward(_pose(m, **curl))
    names = list(m.end_site_names)
    tip = res.end_sites[0, names.index("r_index_tip")]
    wrist = res.joints[0, m.joint_index("r_wrist")]
    rest_tip = m.end_sites_rest[names.index("r_index_tip")]
    assert np.linalg.norm(tip - wrist) < np.linalg.norm(rest_tip - m.joints_rest[m.joint_index("r_wrist")]) - 0.04


# --------------------------------------------------------------------------- FK / LBS
def test_rest_pose_reproduces_rest_mesh(model):
    for backend in ("numba", "numpy"):
        verts, joints = model.pose(model.rest_pose()[None], backend=backend)
        np.testing.assert_allclose(verts[0], model.vertices, atol=1e-5)
        np.testing.assert_allclose(joints[0], model.joints_rest, atol=1e-12)


def test_fk_preserves_bone_lengths(tracking):
    m = tracking
    params = sample_pose(m.skeleton, rng_for(3), 300)
    params[:, :3] = rng_for(4).normal(size=(300, 3))
    rot, root_t = pose_to_local_rotations(m.skeleton, params)
    tf, pos = forward_kinematics(rot, root_t, m.joints_rest, m.parents)
    rest_len = np.linalg.norm(m.joints_rest[1:] - m.joints_rest[m.parents[1:]], axis=-1)
    posed_len = np.linalg.norm(pos[:, 1:] - pos[:, m.parents[1:]], axis=-1)
    np.testing.assert_allclose(posed_len, np.broadcast_to(rest_len, posed_len.shape), atol=1e-9)
    np.testing.assert_allclose(pos[:, 0], root_t)
    np.testing.assert_allclose(tf[..., :3, 3], pos)
    g = tf[..., :3, :3]
    np.testing.assert_allclose(np.linalg.det(g), 1.0, atol=1e-9)


def test_posed_mesh_stays_watertight(model):
    params = sample_pose(model.skeleton, rng_for(5), 8, scale=0.6)
    verts, joints = model.pose(params)
    assert np.all(np.isfinite(verts)) and np.all(np.isfinite(joints))
    assert not np.allclose(verts, model.vertices[None], atol=1e-3)
    rest_volume = trimesh.Trimesh(model.vertices, model.faces, process=False).volume
    for v in verts:
        mesh = trimesh.Trimesh(v, model.faces, process=False)
        assert mesh.is_watertight and mesh.is_winding_consistent
        assert mesh.volume == pytest.approx(rest_volume, rel=0.25)


def test_batch_equals_one_at_a_time(tracking):
    m = tracking
    params = sample_pose(m.skeleton, rng_for(6), 6)
    shapes = sample_shape(rng_for(7), 6)
    params[:, :3] = m.rest_pose(shapes)[:, :3]
    verts, joints = m.pose(params, shapes)
    for i in range(len(params)):
        one = BodyShape(shapes.bone_scale[i], shapes.radial_scale[i], float(shapes.global_scale[i]))
        v, j = m.pose(params[i], one)
        np.testing.assert_allclose(v, verts[i], atol=2e-5)
        np.testing.assert_allclose(j, joints[i], atol=1e-9)


def test_numba_and_numpy_lbs_agree(model):
    params = sample_pose(model.skeleton, rng_for(8), 4)
    rot, root_t = pose_to_local_rotations(model.skeleton, params)
    tf, _ = forward_kinematics(rot, root_t, model.joints_rest, model.parents)
    mats = skinning_matrices(tf, model.joints_rest)
    a = skin_vertices(mats, model.vertices, model.sparse_weights, backend="numba")
    b = skin_vertices(mats, model.vertices, model.weights, backend="numpy")
    np.testing.assert_allclose(a, b, atol=2e-5)


def test_end_sites_move_rigidly_with_parent(tracking):
    m = tracking
    res = m.forward(sample_pose(m.skeleton, rng_for(9), 20))
    rest_len = np.linalg.norm(m.end_sites_rest - m.joints_rest[m.end_site_parents], axis=-1)
    posed_len = np.linalg.norm(res.end_sites - res.joints[:, m.end_site_parents], axis=-1)
    np.testing.assert_allclose(posed_len, np.broadcast_to(rest_len, posed_len.shape), atol=1e-9)


# --------------------------------------------------------------------------- anthropometry
def test_neutral_shape_is_identity(model):
    rest = apply_shape(model, BodyShape.neutral())
    np.testing.assert_allclose(rest.vertices, model.vertices, atol=1e-6)
    np.testing.assert_allclose(rest.joints, model.joints_rest, atol=1e-12)
    assert BodyShape.neutral().height(model) == pytest.approx(model.height, abs=1e-6)
    assert shape_log_prior(model, BodyShape.neutral()) == pytest.approx(0.0, abs=1e-9)


def test_shape_scaling_changes_height_as_expected(tracking):
    m = tracking
    n = BodyShape.neutral()
    legs = np.linalg.norm(m.joints_rest[m.joint_index("l_knee")] - m.joints_rest[m.joint_index("l_hip")]) \
        + np.linalg.norm(m.joints_rest[m.joint_index("l_ankle")] - m.joints_rest[m.joint_index("l_knee")])
    leg_drop = m.joints_rest[m.joint_index("l_hip"), 1] - m.joints_rest[m.joint_index("l_ankle"), 1]
    assert n.with_entity("legs", bone=1.1).height(m) - m.height == pytest.approx(0.1 * leg_drop, rel=0.05)
    glob = BodyShape(n.bone_scale, n.radial_scale, 1.1)
    assert glob.height(m) == pytest.approx(1.1 * m.height, rel=1e-6)
    sizes = entity_sizes(m, n.with_entity("legs", bone=1.1))
    assert sizes[ENTITY_NAMES.index("legs")] == pytest.approx(1.1 * legs, rel=1e-6)
    # radial scale thickens without changing bone lengths or height
    thick = n.with_entity("upperarms", radial=1.3)
    rest = apply_shape(m, thick)
    np.testing.assert_allclose(rest.joints, m.joints_rest, atol=1e-9)
    arm = m.vertex_part == m.joint_index("l_shoulder")
    axis_pt = m.joints_rest[m.joint_index("l_shoulder")]
    d = m.joints_rest[m.joint_index("l_elbow")] - axis_pt
    d /= np.linalg.norm(d)

    def girth(v):
        rel = v[arm] - axis_pt
        return np.linalg.norm(rel - (rel @ d)[:, None] * d, axis=1).mean()

    assert girth(rest.vertices) > 1.15 * girth(m.vertices)
    mesh = trimesh.Trimesh(rest.vertices, m.faces, process=False)
    assert mesh.volume > trimesh.Trimesh(m.vertices, m.faces, process=False).volume


def test_shaped_fk_bone_lengths(tracking):
    m = tracking
    shapes = sample_shape(rng_for(10), 50)
    rest = apply_shape(m, shapes)
    params = sample_pose(m.skeleton, rng_for(11), 50)
    params[:, :3] = rest.joints[:, 0]
    res = m.forward(params, shapes)
    rest_len = np.linalg.norm(rest.joints[:, 1:] - rest.joints[:, m.parents[1:]], axis=-1)
    posed_len = np.linalg.norm(res.joints[:, 1:] - res.joints[:, m.parents[1:]], axis=-1)
    np.testing.assert_allclose(posed_len, rest_len, atol=1e-9)
    # standing subjects stay on the floor
    stand = m.forward(m.rest_pose(shapes), shapes)
    np.testing.assert_allclose(stand.vertices[..., 1].min(-1), m.vertices[:, 1].min(), atol=1e-5)


def test_sample_shape_follows_priors(tracking):
    a = sample_shape(rng_for(12), 400)
    b = sample_shape(rng_for(12), 400)
    np.testing.assert_array_equal(a.to_vector(), b.to_vector())  # seeded, repeatable
    h = a.height(tracking)
    assert abs(h.mean() - tracking.height) < 0.02 and 0.03 < h.std() < 0.12
    sizes = entity_sizes(tracking, a)
    base = entity_sizes(tracking)
    for name, (mean_cm, var_cm2) in TABLE_2_1.items():
        if name in ("shoulder_height", "arms"):
            continue  # aggregates: spread comes from their parts
        k = ENTITY_NAMES.index(name)
        rel = sizes[:, k].std() / base[k]
        assert 0.5 * np.sqrt(var_cm2) / mean_cm < rel < 2.0 * np.sqrt(var_cm2) / mean_cm + 0.05, name
    single = sample_shape(rng_for(13))
    assert not single.batched and isinstance(single.height(tracking), float | np.floating)
    round_trip = BodyShape.from_vector(a.to_vector())
    np.testing.assert_array_equal(round_trip.bone_scale, a.bone_scale)


def test_rest_pose_helper(tracking):
    np.testing.assert_array_equal(rest_pose(tracking.skeleton)[:3], tracking.joints_rest[0])
    shapes = sample_shape(rng_for(14), 3)
    p = tracking.rest_pose(shapes)
    assert p.shape == (3, tracking.skeleton.n_dofs)
    np.testing.assert_allclose(p[:, :3], apply_shape(tracking, shapes).joints[:, 0])


def test_body_shape_from_named_entities():
    from hmocap_ros.body import ENTITY_NAMES, BodyShape

    shape = BodyShape.from_named(["legs", "head"], [1.1, 0.9], [1.2, 0.8], 1.05)
    assert shape.entity("legs") == (1.1, 1.2) and shape.entity("head") == (0.9, 0.8)
    others = [n for n in ENTITY_NAMES if n not in ("legs", "head")]
    assert all(shape.entity(n) == (1.0, 1.0) for n in others)
    assert float(shape.global_scale) == 1.05
    with pytest.raises(ValueError, match="unknown body entities tail"):
        BodyShape.from_named(["tail"], [1.0], [1.0])
    with pytest.raises(ValueError, match="2 entity names for 1 bone"):
        BodyShape.from_named(["legs", "head"], [1.0], [1.0, 1.0])
