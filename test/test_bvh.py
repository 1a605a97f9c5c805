"""BVH parser, forward kinematics and retargeting onto the body (hmocap_sim.bvh / retarget)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import hmocap_ros
from hmocap_sim import bvh as bvh_mod
from hmocap_sim import retarget as rt

DATA = Path(__file__).parent / "data"
CLIPS = Path(hmocap_ros.__file__).parent / "data" / "bvh"
PACKAGE_BODY = Path(hmocap_ros.__file__).parent / "data" / "body_tracking.npz"

# Shipped clip -> (family, frames dropped as an added T-pose and its blend).
SHIPPED = {
    "09_01.bvh": ("cmu_mb", 1),
    "13_26.bvh": ("cmu_mb", 1),
    "14_19_first1201.bvh": ("daz", 4),
    "002_01.bvh": ("cc_base", 0),
}
LIMBS = [
    f"{s}_{a}->{s}_{b}" for s in "lr" for a, b in (
        ("clavicle", "shoulder"), ("shoulder", "elbow"), ("elbow", "wrist"), ("wrist", "hand_tip"),
        ("hip", "knee"), ("knee", "ankle"), ("ankle", "toe"),
    )
]


def clip(name: str) -> Path:
    path = CLIPS / name
    assert path.is_file(), f"{path} is missing: the clip is shipped with the package"
    return path


# ---------------------------------------------------------------------------- body models


def synthetic_body() -> dict:
    """A hand-written 19-joint A-pose body (metres, +Y up, facing +Z, +X left): not the
    MakeHuman one, to show that retargeting takes the body as input."""
    names = ["pelvis", "spine", "chest", "neck", "head", "l_clavicle", "l_shoulder", "l_elbow",
             "l_wrist", "r_clavicle", "r_shoulder", "r_elbow", "r_wrist", "l_hip", "l_knee",
             "l_ankle", "r_hip", "r_knee", "r_ankle"]
    parents = [-1, 0, 1, 2, 3, 2, 5, 6, 7, 2, 9, 10, 11, 0, 13, 14, 0, 16, 17]
    half = {
        "pelvis": (0, 0.95, 0), "spine": (0, 1.00, -0.02), "chest": (0, 1.30, -0.02),
        "neck": (0, 1.46, -0.01), "head": (0, 1.56, 0.0), "clavicle": (0.03, 1.40, 0.05),
        "shoulder": (0.18, 1.41, 0.0), "elbow": (0.33, 1.20, 0.0), "wrist": (0.45, 1.00, 0.05),
        "hip": (0.10, 0.92, 0.0), "knee": (0.13, 0.50, 0.02), "ankle": (0.15, 0.08, -0.01),
        "hand_tip": (0.52, 0.85, 0.10), "toe": (0.17, 0.02, 0.14), "head_top": (0, 1.72, 0),
    }

    def point(name: str) -> tuple:
        if name[:2] in ("l_", "r_"):
            x, y, z = half[name[2:]]
            return (x if name[0] == "l" else -x, y, z)
        return half[name]

    sites = ["head_top", "l_hand_tip", "r_hand_tip", "l_toe", "r_toe"]
    return dict(
        body_rest_joints=np.array([point(n) for n in names], dtype=float),
        body_parents=np.array(parents),
        joint_names=names,
        end_sites_rest=np.array([point(n) for n in sites], dtype=float),
        end_site_parents=np.array([names.index(n) for n in ("head", "l_wrist", "r_wrist",
                                                               "l_ankle", "r_ankle")]),
        end_site_names=sites,
    )


def body_from_npz(path: Path) -> dict:
    """The skeleton of a body asset (joints, parents and end sites of the rest pose)."""
    data = np.load(path, allow_pickle=False)
    return dict(
        body_rest_joints=data["joints_rest"].astype(float),
        body_parents=data["parents"],
        joint_names=[str(n) for n in data["joint_names"]],
        end_sites_rest=data["end_sites_rest"].astype(float),
        end_site_parents=data["end_site_parents"],
        end_site_names=[str(n) for n in data["end_site_names"]],
    )


@pytest.fixture(params=["synthetic", "package"])
def body(request) -> dict:
    """The hand-written body, and the package's tracking body (data/body_tracking.npz)."""
    if request.param == "synthetic":
        return synthetic_body()
    return body_from_npz(PACKAGE_BODY)


_MOTIONS: dict = {}


def retargeted(name: str, body: dict, frames=slice(0, 600)) -> tuple:
    """(bvh, motion) for a shipped clip, cached across tests (retargeting is the slow part)."""
    key = (name, tuple(body["joint_names"]), body["body_rest_joints"].tobytes(), str(frames))
    if key not in _MOTIONS:
        bvh = bvh_mod.load_bvh(clip(name))
        _MOTIONS[key] = (bvh, rt.retarget(bvh, **body, frames=frames))
    return _MOTIONS[key]


# --------------------------------------------------------------------------- parser and FK


def test_tiny_chain_structure():
    bvh = bvh_mod.load_bvh(DATA / "tiny_chain.bvh")
    assert bvh.joint_names == ("root", "a", "b", "c")
    assert bvh.parents.tolist() == [-1, 0, 1, 0]
    assert bvh.channels[0] == ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation",
                               "Yrotation")
    assert bvh.channels[2] == ("Yrotation", "Zrotation", "Xrotation")
    assert bvh.channel_start.tolist() == [0, 6, 9, 12]
    assert bvh.end_site_names == ("b_end", "c_end")
    assert bvh.end_site_parents.tolist() == [2, 3]
    assert bvh.motion.shape == (6, 15)
    assert bvh.fps == 30.0
    assert bvh_mod.detect_family(bvh) is None


def test_tiny_chain_forward_kinematics_by_hand():
    """Expected positions worked out by hand from Rx/Ry/Rz(90) applied in channel order."""
    bvh = bvh_mod.load_bvh(DATA / "tiny_chain.bvh")
    pose = bvh_mod.forward_kinematics(bvh)
    # joints root, a, b, c, then End Sites b_end, c_end
    expected = np.array([
        [(0, 0, 0), (0, 10, 0), (5, 10, 0), (-3, 0, 0), (5, 10, 2), (-3, -4, 0)],  # rest
        [(1, 2, 3), (-9, 2, 3), (-9, 7, 3), (1, -1, 3), (-9, 7, 5), (5, -1, 3)],  # root Rz 90
        [(0, 0, 0), (0, 10, 0), (0, 15, 0), (-3, 0, 0), (2, 15, 0), (-3, -4, 0)],  # a: Rx Ry
        [(0, 0, 0), (0, 10, 0), (5, 10, 0), (-3, 0, 0), (5, 10, -2), (-3, -4, 0)],  # b: Ry Rz Rx
        [(0, 0, 0), (0, 10, 0), (5, 10, 0), (-3, 0, 0), (5, 10, 2), (-3, 0, -4)],  # c: Rx 90
        [(0, 0, 0), (0, 0, 10), (0, 5, 10), (0, -3, 0), (2, 5, 10), (0, -3, -4)],  # root Rz Rx
    ], dtype=float)
    got = np.concatenate([pose.positions, pose.end_sites], axis=1)
    np.testing.assert_allclose(got, expected, atol=1e-9)
    np.testing.assert_allclose(pose.point(bvh, "c_end"), expected[:, 5], atol=1e-9)
    rot = pose.rotations
    identity = np.broadcast_to(np.eye(3), rot.shape)
    np.testing.assert_allclose(rot @ np.swapaxes(rot, -1, -2), identity, atol=1e-12)
    # unit scale and frame selection
    scaled = bvh_mod.forward_kinematics(bvh, frames=[1, 5], scale=0.01)
    np.testing.assert_allclose(scaled.positions, 0.01 * expected[[1, 5], :4], atol=1e-12)


@pytest.mark.parametrize("order", ["ZYX", "ZXY", "XYZ", "YZX", "YXZ", "XZY"])
def test_euler_to_matrix_matches_intrinsic_scipy(order):
    angles = np.random.default_rng(0).uniform(-180, 180, size=(20, 3))
    expected = Rotation.from_euler(order.upper(), angles, degrees=True).as_matrix()
    np.testing.assert_allclose(bvh_mod.euler_to_matrix(angles, order), expected, atol=1e-12)


def _tiny_lines() -> list[str]:
    return (DATA / "tiny_chain.bvh").read_text().splitlines()


def _first_frame_line() -> int:
    lines = _tiny_lines()
    return next(i for i, line in enumerate(lines) if line.startswith("Frame Time")) + 2


def _mutate(kind: str) -> str:
    lines = _tiny_lines()
    first = _first_frame_line() - 1  # 0-based index of frame 0
    if kind == "missing_value":
        lines[first + 2] = " ".join(lines[first + 2].split()[:-1])
    elif kind == "extra_value":
        lines[first + 1] += " 7"
    elif kind == "not_a_number":
        lines[first + 3] = lines[first + 3].replace("90", "ninety", 1)
    elif kind == "missing_motion":
        lines = lines[: lines.index("MOTION")]
    elif kind == "fewer_frames":
        lines = lines[:-2]
    elif kind == "cut_mid_line":
        lines[-1] = " ".join(lines[-1].split()[:7])
    elif kind == "extra_frame":
        lines.append(lines[-1])
    elif kind == "bad_channel":
        lines = [line.replace("Yrotation Zrotation Xrotation", "Yrotation Zrot Xrotation")
                 for line in lines]
    elif kind == "channel_count":
        lines = [line.replace("CHANNELS 3 Xrotation", "CHANNELS 4 Xrotation") for line in lines]
    elif kind == "unclosed_brace":
        lines.remove(lines[lines.index("MOTION") - 1])
    elif kind == "no_frame_time":
        lines = [line for line in lines if not line.startswith("Frame Time")]
    elif kind == "not_bvh":
        lines = ["hello world"]
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("kind, message", [
    ("missing_value", r"line {f2}: frame 2 has 14 values, expected 15"),
    ("extra_value", r"line {f1}: frame 1 has 16 values, expected 15"),
    ("not_a_number", r"line {f3}: 'ninety' is not a number"),
    ("missing_motion", r"no MOTION section"),
    ("fewer_frames", r"file ends after 4 frame lines but 'Frames:' .* says 6: .*truncated"),
    ("cut_mid_line", r"line {f5}: frame 5 has 7 values, expected 15: the file is truncated"),
    ("extra_frame", r"line {f6}: more frame lines \(7\) than 'Frames:'"),
    ("bad_channel", r"line 13: CHANNELS of 'b': 'Zrot' is not one of"),
    ("channel_count", r"line (9|10): CHANNELS of 'a': 'JOINT' is not one of .* count 4"),
    ("unclosed_brace", r"HIERARCHY ends early"),
    ("no_frame_time", r"line {f_1}: expected 'Frame Time: <number>', found '0 0 0"),
    ("not_bvh", r"line 1: expected 'HIERARCHY'"),
])
def test_malformed_files_name_the_line(tmp_path, kind, message):
    first = _first_frame_line()  # 1-based line of frame 0
    pattern = message.format(f_1=first - 1, **{f"f{i}": first + i for i in range(7)})
    path = tmp_path / f"{kind}.bvh"
    path.write_text(_mutate(kind))
    with pytest.raises(bvh_mod.BvhError, match=pattern) as info:
        bvh_mod.load_bvh(path)
    assert str(path) in str(info.value)


def test_parse_bvh_from_string_and_crlf():
    text = (DATA / "tiny_chain.bvh").read_text().replace("\n", "\r\n")
    bvh = bvh_mod.parse_bvh(text)
    assert bvh.source == "<string>" and bvh.n_frames == 6 and bvh.n_joints == 4


# ------------------------------------------------------------------------ shipped families


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_shipped_clip_parses_and_is_a_person(name):
    family, _ = SHIPPED[name]
    bvh = bvh_mod.load_bvh(clip(name))
    assert bvh_mod.detect_family(bvh) == family
    assert bvh.fps in (60.0, 120.0)
    assert bvh.motion.shape == (bvh.n_frames, sum(len(c) for c in bvh.channels))
    n = min(bvh.n_frames, 200) - 1
    pose = bvh_mod.forward_kinematics(bvh, frames=slice(1, n + 1),
                                      scale=bvh_mod.FAMILY_UNITS_M[family])
    assert pose.positions.shape == (n, bvh.n_joints, 3)
    assert pose.end_sites.shape == (n, len(bvh.end_site_names), 3)
    # In metres and +Y up: the head is 1.3-2.0 m above the lowest foot point.
    head = {"cmu_mb": "Head", "daz": "head", "cc_base": "CC_Base_Head"}[family]
    height = pose.point(bvh, head)[:, 1] - pose.end_sites[..., 1].min(axis=1)
    assert np.all((height > 1.2) & (height < 2.0)), height.min()


def test_family_detection_needs_the_names():
    bvh = bvh_mod.load_bvh(clip("09_01.bvh"))
    renamed = bvh_mod.Bvh(**{**bvh.__dict__, "joint_names": tuple(
        n.replace("Left", "Port") for n in bvh.joint_names)})
    assert bvh_mod.detect_family(renamed) is None
    with pytest.raises(ValueError, match="unknown BVH skeleton family"):
        rt.retarget(renamed, **synthetic_body())


# ---------------------------------------------------------------------------- retargeting


def test_kabsch_and_swing_recover_rotations():
    rng = np.random.default_rng(1)
    truth = Rotation.random(50, random_state=2).as_matrix()
    a = rng.normal(size=(4, 3))
    b = np.einsum("fij,nj->fni", truth, a)
    np.testing.assert_allclose(rt.kabsch(a, b), truth, atol=1e-10)
    u, v = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    v[0] = -u[0]  # opposite directions: a half turn
    r = rt.swing(u, v)
    np.testing.assert_allclose(np.einsum("fij,fj->fi", r, rt.unit_vectors(u)), rt.unit_vectors(v), atol=1e-10)
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-10)


@pytest.mark.parametrize("up", [(0, 0, 1), (0, 0, -1), (1, 0, 0), (0, -1, 0), (0, 1, 0)])
def test_up_axis_rotation_puts_up_on_plus_y(up):
    r = rt.up_axis_rotation(np.array(up, float) + 0.1)
    np.testing.assert_allclose(r @ np.array(up, float), [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(r), 1.0)


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_retarget_drops_added_t_pose(name):
    family, dropped = SHIPPED[name]
    _, motion = retargeted(name, synthetic_body())
    assert motion.family == family
    assert motion.source_frames[0] == dropped
    assert motion.local_rotations.shape == (motion.n_frames, 19, 3, 3)
    assert motion.root_translation.shape == (motion.n_frames, 3)


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_retarget_keeps_body_bone_lengths_and_bvh_directions(name, body):
    bvh, motion = retargeted(name, body)
    rest, parents = body["body_rest_joints"], body["body_parents"]
    rot = motion.local_rotations
    identity = np.broadcast_to(np.eye(3), rot.shape)
    np.testing.assert_allclose(rot @ np.swapaxes(rot, -1, -2), identity, atol=1e-9)
    positions, _ = rt.joint_forward_kinematics(rot, motion.root_translation, rest, parents)
    child = np.flatnonzero(parents >= 0)
    lengths = np.linalg.norm(positions[:, child] - positions[:, parents[child]], axis=-1)
    rest_lengths = np.linalg.norm(rest[child] - rest[parents[child]], axis=-1)
    np.testing.assert_allclose(lengths, np.broadcast_to(rest_lengths, lengths.shape), atol=1e-9)

    errors = rt.bone_direction_errors(
        motion, bvh, rest, parents, body["end_sites_rest"], body["end_site_parents"],
        body["end_site_names"])
    for bone in LIMBS + ["spine->chest", "neck->head", "head->head_top"]:
        assert np.median(errors[bone]) < 5.0, (bone, np.median(errors[bone]))
        assert np.percentile(errors[bone], 95) < 5.0, bone


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_retarget_torso_twist_follows_the_bvh(name):
    """Kabsch joints: the pelvis's left axis follows the BVH hip line, the head's the eye line."""
    bvh, motion = retargeted(name, synthetic_body())
    body = synthetic_body()
    _, glob = rt.joint_forward_kinematics(motion.local_rotations, motion.root_translation, body["body_rest_joints"],
                     body["body_parents"])
    pose = bvh_mod.forward_kinematics(bvh, frames=motion.source_frames)
    marks = rt.FAMILY_LANDMARKS[motion.family]

    def line(a, b):
        v = rt.bvh_point(bvh, pose, marks[a]) - rt.bvh_point(bvh, pose, marks[b])
        return rt.unit_vectors(v @ motion.bvh_to_body.T)

    def angle(u, v):
        return np.degrees(np.arccos(np.clip(np.einsum("fi,fi->f", u, v), -1, 1)))

    assert np.median(angle(glob[:, 0, :, 0], line("l_hip", "r_hip"))) < 10.0
    if "l_eye" in marks:
        head = body["joint_names"].index("head")
        assert np.median(angle(glob[:, head, :, 0], line("l_eye", "r_eye"))) < 10.0


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_retarget_feet_on_the_floor(name, body):
    _, motion = retargeted(name, body)
    rest, parents = body["body_rest_joints"], body["body_parents"]
    positions, glob = rt.joint_forward_kinematics(motion.local_rotations, motion.root_translation, rest, parents)
    sites = rt.end_site_forward_kinematics(positions, glob, rest, body["end_sites_rest"],
                             body["end_site_parents"])
    feet = [body["joint_names"].index(n) for n in ("l_ankle", "r_ankle")]
    toes = [body["end_site_names"].index(n) for n in ("l_toe", "r_toe")]
    above_rest = np.concatenate([
        positions[:, feet, 1] - rest[feet, 1],
        sites[:, toes, 1] - body["end_sites_rest"][toes, 1]], axis=1).min(axis=1)
    assert abs(np.percentile(above_rest, 10)) < 0.005
    assert above_rest.min() > -0.05
    assert np.median(above_rest) < 0.10
    pelvis_height = motion.root_translation[:, 1]
    assert 0.5 < np.median(pelvis_height) < 1.2


def test_load_motion_with_resampling(body):
    motion = rt.load_motion(clip("09_01.bvh"), **body, fps=30)
    assert motion.fps == 30 and motion.source_frames is None
    assert motion.n_frames == round((149 - 2) * 30 / 120) + 1


def test_resample_keeps_ends_and_interpolates():
    _, motion = retargeted("09_01.bvh", synthetic_body())
    for fps in (30.0, 50.0, 240.0):
        out = rt.resample(motion, fps)
        assert out.fps == fps
        assert out.n_frames == round(motion.duration * fps) + 1
        np.testing.assert_array_equal(out.local_rotations[[0, -1]], motion.local_rotations[[0, -1]])
        np.testing.assert_array_equal(out.root_translation[[0, -1]],
                                      motion.root_translation[[0, -1]])
        rot = out.local_rotations
        np.testing.assert_allclose(rot @ np.swapaxes(rot, -1, -2),
                                   np.broadcast_to(np.eye(3), rot.shape), atol=1e-9)
    double = rt.resample(motion, 2 * motion.fps)
    np.testing.assert_allclose(double.local_rotations[::2], motion.local_rotations, atol=1e-9)
    # a midpoint is the half-way slerp
    mid = Rotation.from_matrix(double.local_rotations[1, 7])
    a, b = (Rotation.from_matrix(motion.local_rotations[i, 7]) for i in (0, 1))
    half = a * Rotation.from_rotvec(0.5 * (a.inv() * b).as_rotvec())
    assert (mid.inv() * half).magnitude() < 1e-9
    np.testing.assert_allclose(double.root_translation[1],
                               motion.root_translation[:2].mean(axis=0), atol=1e-12)


@pytest.mark.parametrize("anchor", ["mean", "first"])
def test_place_in_room(anchor):
    body = synthetic_body()
    _, motion = retargeted("002_01.bvh", body)
    placed = rt.place_in_room(motion, (1.5, -0.5), np.pi / 2, anchor=anchor)
    pelvis = placed.root_translation
    where = pelvis.mean(axis=0) if anchor == "mean" else pelvis[0]
    np.testing.assert_allclose(where[[0, 2]], [1.5, -0.5], atol=1e-9)
    assert rt.heading_of(placed) == pytest.approx(np.pi / 2)
    np.testing.assert_allclose(pelvis[:, 1], motion.root_translation[:, 1])
    # same pose up to a rigid motion about the vertical: joint heights are unchanged
    before, _ = rt.joint_forward_kinematics(motion.local_rotations, motion.root_translation,
                       body["body_rest_joints"], body["body_parents"])
    after, _ = rt.joint_forward_kinematics(placed.local_rotations, placed.root_translation,
                      body["body_rest_joints"], body["body_parents"])
    np.testing.assert_allclose(after[..., 1], before[..., 1], atol=1e-9)
    step_before = np.linalg.norm(np.diff(before, axis=0), axis=-1)
    step_after = np.linalg.norm(np.diff(after, axis=0), axis=-1)
    np.testing.assert_allclose(step_after, step_before, atol=1e-9)


def test_motion_drives_the_body_kinematics():
    """The Motion convention is the one of hmocap_ros.body.kinematics.forward_kinematics."""
    from hmocap_ros.body import kinematics

    body = synthetic_body()
    _, motion = retargeted("002_01.bvh", body)
    ours, _ = rt.joint_forward_kinematics(motion.local_rotations, motion.root_translation, body["body_rest_joints"],
                     body["body_parents"])
    _, theirs = kinematics.forward_kinematics(motion.local_rotations, motion.root_translation,
                                              body["body_rest_joints"], body["body_parents"])
    np.testing.assert_allclose(theirs, ours, atol=1e-9)
