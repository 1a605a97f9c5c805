"""``hmocap export``: BVH, TRC and CSV of a bag's body motion, read back and compared with the
bag's skeleton messages.

Two bags: a short simulated recording (2 cameras at 160x120, 10 frames; its ground truth is
exported with ``--source truth``) and a bag written as body_tracker writes its output
(``skeleton`` for two bodies, ``joint_states`` and latched ``body_shape`` of the first on the
plain topics, the second's under ``humans/bodies/body_1/``), at the root namespace and under
``/room``. The BVH goes through the package's own BVH reader and forward kinematics.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from hmocap_ros import cli
from hmocap_ros.body import load_body_model, sample_pose, sample_shape
from hmocap_ros.export.bvh_writer import matrix_to_euler
from hmocap_ros.export.motion import read_motion
from hmocap_ros.io.bag_writer import LATCHED, BagWriter
from hmocap_ros.io.joint_states import make_joint_state
from hmocap_ros.io.msg_factory import RosbagsFactory, make_header
from hmocap_ros.io.typestore import hmocap_typestore
from hmocap_sim.bvh import euler_to_matrix, forward_kinematics, load_bvh

#: The BVH's End Sites (``<joint>_end`` in the reader) and the skeleton's end-site names.
END_SITES = {"head_end": "head_top", "l_wrist_end": "l_hand_tip", "r_wrist_end": "r_hand_tip",
             "l_ankle_end": "l_toe", "r_ankle_end": "r_toe"}
TRACKER_FRAMES = 8
STAMP0 = 1_700_000_000_000_000_000


@pytest.fixture(scope="module")
def sim_bag(tmp_path_factory) -> Path:
    from hmocap_sim.mocap_dataset import MocapSimConfig, generate

    out = tmp_path_factory.mktemp("sim") / "run.mcap"
    generate(MocapSimConfig(out=out, cameras=2, width=160, height=120, start=2.0, seconds=0.4,
                            background_seconds=0.0, contact_frames=0, noise=False, shadows=False,
                            progress=False))
    return out


def _skeleton_msg(factory, stamp, body_id, model, joints):
    return factory.make(
        "hmocap_interfaces/msg/Skeleton", header=make_header(factory, stamp, "room"), body_id=body_id,
        joint_names=list(model.joint_names),
        positions=[factory.make("geometry_msgs/msg/Point", x=float(p[0]), y=float(p[1]), z=float(p[2]))
                   for p in joints],
        parents=np.asarray(model.parents, np.int32), confidence=np.zeros(0, np.float32), fit_error=0.1)


def _shape_msg(factory, stamp, body_id, shape, model):
    return factory.make(
        "hmocap_interfaces/msg/BodyShape", header=make_header(factory, stamp, "room"), body_id=body_id,
        entity_names=list(shape.entity_names), bone_scale=np.asarray(shape.bone_scale, np.float32),
        radial_scale=np.asarray(shape.radial_scale, np.float32), global_scale=float(shape.global_scale),
        height=float(shape.height(model)))


@pytest.fixture(scope="module", params=["/", "/room/"], ids=["root_ns", "room_ns"])
def tracker_bag(request, tmp_path_factory):
    """A bag of body_tracker output for body_0 and body_1 under namespace ``request.param``."""
    ns = request.param
    model = load_body_model("tracking")
    rng = np.random.default_rng(7)
    factory = RosbagsFactory(hmocap_typestore())
    stamps = STAMP0 + np.arange(TRACKER_FRAMES, dtype=np.int64) * 40_000_000
    path = tmp_path_factory.mktemp("tracker") / "body.mcap"
    topics = {"body_0": (f"{ns}joint_states", f"{ns}body_shape"),
              "body_1": (f"{ns}humans/bodies/body_1/joint_states", f"{ns}humans/bodies/body_1/body_shape")}
    truth = {}
    with BagWriter(path) as bag:
        for body, (_js_topic, shape_topic) in topics.items():
            bag.add_topic(shape_topic, "hmocap_interfaces/msg/BodyShape", LATCHED)
            shape = sample_shape(rng)
            params = sample_pose(model.skeleton, rng, TRACKER_FRAMES, scale=1.0,
                                 root_translation=[rng.uniform(-1, 1), 0.95, rng.uniform(-1, 1)])
            joints = model.forward(params, shape).joints
            bag.write(shape_topic, _shape_msg(factory, int(stamps[0]), body, shape, model), int(stamps[0]))
            truth[body] = (params, joints)
        for i, stamp in enumerate(stamps.tolist()):
            for body, (js_topic, _) in topics.items():
                params, joints = truth[body]
                bag.write(js_topic, make_joint_state(model.skeleton.dof_names, params[i], stamp, "room",
                                                     factory=factory), stamp)
                bag.write(f"{ns}skeleton", _skeleton_msg(factory, stamp, body, model, joints[i]), stamp)
    return path, stamps, truth


def _export(argv, capsys) -> tuple[int, str, str]:
    capsys.readouterr()
    status = cli.main(["export", *map(str, argv)])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def _bvh_points(path: Path, names) -> np.ndarray:
    """(F, P, 3) metres of the skeleton points ``names`` from a BVH file by the package's reader."""
    bvh = load_bvh(path)
    pose = forward_kinematics(bvh, scale=0.01)
    ends = {END_SITES[n]: k for k, n in enumerate(bvh.end_site_names)}
    return np.stack([pose.positions[:, bvh.joint_names.index(n)] if n in bvh.joint_names
                     else pose.end_sites[:, ends[n]] for n in names], axis=1)


def test_matrix_to_euler_inverts_bvh_rotations():
    rng = np.random.default_rng(0)
    for order in ("XYZ", "YZX", "ZXY", "XZY", "ZYX", "YXZ"):
        angles = rng.uniform(-180, 180, (200, 3)) * [1, 0.5, 1]
        angles[:3, 1], angles[3:6, 1] = 90.0, -90.0  # the Euler lock
        r = euler_to_matrix(angles, order)
        assert np.abs(euler_to_matrix(matrix_to_euler(r, order), order) - r).max() < 1e-12, order


def test_bvh_of_simulated_truth_reproduces_the_skeleton(sim_bag, tmp_path, capsys):
    out = tmp_path / "truth.bvh"
    status, stdout, err = _export([sim_bag, "--format", "bvh", "--source", "truth", "--out", out], capsys)
    assert status == 0, err
    assert "10 frames of body_0" in stdout
    motion = read_motion(sim_bag, "truth")
    bvh = load_bvh(out)  # the reader checks one value per channel on every frame line
    model = load_body_model("tracking")
    assert bvh.joint_names == model.joint_names
    assert np.array_equal(bvh.parents, model.parents)
    assert bvh.n_frames == motion.n_frames == 10
    assert bvh.motion.shape[1] == 6 + 3 * (model.n_joints - 1)
    assert bvh.fps == 25.0
    err_m = np.linalg.norm(_bvh_points(out, motion.point_names) - motion.points, axis=-1)
    assert err_m.max() < 1e-3, f"BVH round trip error {err_m.max() * 1e3:.4f} mm"


def test_trc_of_simulated_truth(sim_bag, tmp_path, capsys):
    out = tmp_path / "truth.trc"
    status, _, err = _export([sim_bag, "--format", "trc", "--source", "truth", "--out", out], capsys)
    assert status == 0, err
    motion = read_motion(sim_bag, "truth")
    lines = out.read_text().splitlines()
    assert lines[0].split("\t")[:4] == ["PathFileType", "4", "(X/Y/Z)", "truth.trc"]
    header = dict(zip(lines[1].split("\t"), lines[2].split("\t")))
    assert header["Units"] == "mm" and float(header["DataRate"]) == 25.0
    assert int(header["NumFrames"]) == motion.n_frames and int(header["NumMarkers"]) == len(motion.point_names)
    assert lines[3].split("\t")[2::3] == list(motion.point_names)
    assert lines[4].split("\t")[2:5] == ["X1", "Y1", "Z1"] and lines[5] == ""
    table = np.loadtxt(lines[6:], delimiter="\t")
    assert np.array_equal(table[:, 0], np.arange(1, motion.n_frames + 1))
    assert np.allclose(table[:, 1], (motion.stamps_ns - motion.stamps_ns[0]) * 1e-9, atol=5e-7)
    expected = motion.points.reshape(motion.n_frames, -1) * 1000.0
    assert np.abs(table[:, 2:] - expected).max() <= 5e-4 + 1e-9


def test_csv_of_simulated_truth(sim_bag, tmp_path, capsys):
    out = tmp_path / "truth.csv"
    status, _, err = _export([sim_bag, "--format", "csv", "--source", "truth", "--out", out], capsys)
    assert status == 0, err
    motion = read_motion(sim_bag, "truth")
    with out.open(newline="") as f:
        rows = list(csv.reader(f))
    head, body = rows[0], rows[1:]
    n_points = len(motion.point_names)
    assert head[:3] == ["stamp_ns", "time_s", "body_id"]
    assert head[3:6] == [f"{motion.point_names[0]}_{a}" for a in "xyz"]
    assert head[3 + 3 * n_points:] == list(motion.dof_names) and len(motion.dof_names) == 30
    assert [int(r[0]) for r in body] == motion.stamps_ns.tolist()
    assert {r[2] for r in body} == {"body_0"}
    values = np.array([r[3:] for r in body], dtype=np.float64)
    assert np.abs(values[:, :3 * n_points] - motion.points.reshape(len(body), -1)).max() <= 5e-7 + 1e-12
    assert np.abs(values[:, 3 * n_points:] - motion.dofs).max() <= 5e-7 + 1e-12
    assert np.allclose([float(r[1]) for r in body], np.arange(len(body)) * 0.04, atol=1e-9)


@pytest.mark.parametrize("body", ["body_0", "body_1"])
def test_tracker_output_exports_and_reads_back(tracker_bag, tmp_path, capsys, body):
    path, stamps, truth = tracker_bag
    params, joints = truth[body]
    model = load_body_model("tracking")
    status, stdout, err = _export([path, "--format", "bvh", "--body-id", body, "--out", tmp_path / "b.bvh"],
                                  capsys)
    assert status == 0, err
    assert f"{TRACKER_FRAMES} frames of {body} (tracked, bvh)" in stdout
    err_m = np.linalg.norm(_bvh_points(tmp_path / "b.bvh", model.joint_names) - joints, axis=-1)
    assert err_m.max() < 1e-3, f"{body}: BVH round trip error {err_m.max() * 1e3:.4f} mm"

    assert _export([path, "--format", "trc", "--body-id", body, "--out", tmp_path / "b.trc"], capsys)[0] == 0
    table = np.loadtxt(tmp_path / "b.trc", delimiter="\t", skiprows=6)
    assert np.abs(table[:, 2:] - joints.reshape(TRACKER_FRAMES, -1) * 1000).max() <= 5e-4 + 1e-9

    assert _export([path, "--format", "csv", "--body-id", body, "--out", tmp_path / "b.csv"], capsys)[0] == 0
    rows = list(csv.reader((tmp_path / "b.csv").open(newline="")))
    assert rows[0][-30:] == list(model.skeleton.dof_names)
    values = np.array([r[3:] for r in rows[1:]], dtype=np.float64)
    assert [int(r[0]) for r in rows[1:]] == stamps.tolist() and {r[2] for r in rows[1:]} == {body}
    assert np.abs(values[:, :-30] - joints.reshape(TRACKER_FRAMES, -1)).max() <= 5e-7 + 1e-12
    assert np.abs(values[:, -30:] - params).max() <= 5e-7 + 1e-12


def test_default_body_and_output_name(tracker_bag, tmp_path, capsys):
    path, _, _ = tracker_bag
    bag = tmp_path / path.name
    bag.write_bytes(path.read_bytes())
    status, stdout, _ = _export([bag, "--format", "trc"], capsys)
    assert status == 0 and "of body_0 (tracked, trc)" in stdout
    assert (tmp_path / "body.trc").is_file()


def _skeleton_only_bag(path: Path) -> Path:
    model = load_body_model("tracking")
    factory = RosbagsFactory(hmocap_typestore())
    with BagWriter(path) as bag:
        bag.write("/skeleton", _skeleton_msg(factory, STAMP0, "body_0", model, model.joints_rest), STAMP0)
    return path


def _joint_states_only_bag(path: Path) -> Path:
    model = load_body_model("tracking")
    factory = RosbagsFactory(hmocap_typestore())
    with BagWriter(path) as bag:
        bag.write("/joint_states", make_joint_state(model.skeleton.dof_names, np.zeros(30), STAMP0,
                                                    factory=factory), STAMP0)
    return path


def _random_bytes(path: Path) -> Path:
    path.write_bytes(np.random.default_rng(1).bytes(4096))
    return path


BAD_INPUTS = {
    # case: (bag maker, extra arguments, texts the error must hold)
    "missing_file": (lambda d: d / "missing.mcap", ["--format", "csv"], ["missing.mcap", "does not exist"]),
    "corrupt_file": (lambda d: _random_bytes(d / "random.mcap"), ["--format", "trc"],
                     ["random.mcap", "not a readable bag"]),
    "no_skeleton": (lambda d: _joint_states_only_bag(d / "js.mcap"), ["--format", "bvh"],
                    ["no tracked skeleton", "/joint_states"]),
    "no_truth": (lambda d: _skeleton_only_bag(d / "sk.mcap"), ["--format", "trc", "--source", "truth"],
                 ["no truth skeleton", "try --source tracked", "/skeleton"]),
    "bvh_without_joint_states": (lambda d: _skeleton_only_bag(d / "sk.mcap"), ["--format", "bvh"],
                                 ["no joint states of body_0", "the bag has /skeleton"]),
    "unknown_body": (lambda d: _skeleton_only_bag(d / "sk.mcap"), ["--format", "csv", "--body-id", "body_9"],
                     ["no body 'body_9'", "body ids: body_0"]),
}


@pytest.mark.parametrize("case", sorted(BAD_INPUTS))
def test_bad_input_is_one_line_and_exit_2(case, tmp_path, capsys):
    make, extra, texts = BAD_INPUTS[case]
    bag = make(tmp_path)
    out_dir = tmp_path / "out"
    status, _, err = _export([bag, *extra, "--out", out_dir / "motion.txt"], capsys)
    assert status == 2
    assert len(err.strip().splitlines()) == 1 and err.startswith("hmocap export: "), err
    for text in texts:
        assert text in err
    assert not out_dir.exists() or not any(out_dir.iterdir())


def test_output_never_replaces_the_bag(tracker_bag, tmp_path, capsys):
    path, _, _ = tracker_bag
    bag = tmp_path / "run.mcap"
    bag.write_bytes(path.read_bytes())
    status, _, err = _export([bag, "--format", "csv", "--out", bag], capsys)
    assert status == 2 and "replace the bag" in err
    assert bag.read_bytes() == path.read_bytes()
