"""REP-155's kinematic model (ROS4HRI human_description) fitted to a tracked body.

The URDF of :func:`human_urdf` is read back twice: by ROS's own URDF parser
(``urdf_parser_py``, what ROS 2 Jazzy ships as python3-urdf-parser-py; skipped where it is not
installed) and by a forward kinematics written here over the XML tree (``xml.etree``: one
parent per link, one root ``body_<id>``, every joint's links declared). Posed with
:func:`urdf_joint_positions` of a tracked pose, the URDF must put every shoulder, elbow,
wrist, knee and ankle where the tracked body has it: robot_state_publisher then draws the
tracked person.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from hmocap_ros.body.human_description import (
    URDF_JOINTS,
    HumanDimensions,
    dimensions_from_joints,
    human_urdf,
    urdf_joint_names,
    urdf_joint_positions,
    urdf_link_poses,
)
from hmocap_ros.body.model import load_body_model
from hmocap_ros.tracking import body_frames as bf


@pytest.fixture(scope="module")
def model():
    return load_body_model("tracking")


def _pose(model, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    skel = model.skeleton
    params = model.rest_pose().copy()
    angles = np.setdiff1d(np.arange(skel.n_dofs), skel.translation_dofs)
    lo, hi = np.maximum(skel.lower[angles], -0.8), np.minimum(skel.upper[angles], 0.8)
    params[angles] = lo + (hi - lo) * rng.random(angles.size)
    params[skel.translation_dofs] = [rng.uniform(-1, 1), 0.95, rng.uniform(-1, 1)]
    return params


def _tracked(model, seed: int):
    """Joint positions, body and head rotations (REP-155 axes) of a random tracked pose."""
    transforms = bf.joint_transforms(model, _pose(model, seed), model.joints_rest)
    rotations = transforms[:, :3, :3] @ bf.REP155_AXES
    names = list(model.skeleton.joint_names)
    return names, transforms[:, :3, 3], rotations[names.index("pelvis")], rotations[names.index("head")]


def _link_positions(urdf: str, angles: dict, root: np.ndarray) -> dict:
    """The URDF's links posed (:func:`urdf_link_poses`), after checking its tree on the XML:
    one parent per link, every joint's links declared."""
    tree = ET.fromstring(urdf)
    links = {link.get("name") for link in tree.findall("link")}
    children = [j.find("child").get("link") for j in tree.findall("joint")]
    assert len(children) == len(set(children)), "a link with two parents"
    assert all(j.find("parent").get("link") in links and j.find("child").get("link") in links
               for j in tree.findall("joint"))
    assert len(links - set(children)) == 1
    return urdf_link_poses(urdf, angles, root)


@pytest.mark.parametrize("seed", range(4))
def test_the_posed_urdf_puts_the_limbs_where_the_tracked_body_has_them(model, seed):
    names, joints, body, head = _tracked(model, seed)
    height = float(joints[:, 1].max() - joints[:, 1].min()) + 0.2
    dims = dimensions_from_joints(names, joints, height)
    urdf = human_urdf("b3", dims)
    angles = dict(zip(urdf_joint_names("b3"), urdf_joint_positions(names, joints, body, head)))
    at = {n: k for k, n in enumerate(names)}
    root = np.eye(4)
    root[:3, :3] = body
    root[:3, 3] = joints[at["pelvis"]]
    poses = _link_positions(urdf, angles, root)
    for side in "lr":
        # a limb's joints relative to its root: the URDF's shoulders and hips sit on its rigid
        # torso and pelvis, the tracked ones where the clavicles and the pelvis put them
        for a, b, c in (("shoulder", "elbow", "wrist"), ("hip", "knee", "ankle")):
            origin = poses[f"{side}_y_{a}_b3"][:3, 3]
            for joint, link in ((b, f"{side}_{b}_b3"), (c, f"{side}_{c}_b3")):
                got = poses[link][:3, 3] - origin
                expected = joints[at[f"{side}_{joint}"]] - joints[at[f"{side}_{a}"]]
                np.testing.assert_allclose(got, expected, atol=1e-6, err_msg=f"{side}_{joint}, seed {seed}")
    # the head turns with the tracked head
    np.testing.assert_allclose(poses["head_b3"][:3, :3], head, atol=1e-6)


def test_the_rest_pose_hangs_the_limbs_down():
    dims = HumanDimensions.from_height(1.75)
    urdf = human_urdf("b0", dims)
    poses = _link_positions(urdf, dict.fromkeys(urdf_joint_names("b0"), 0.0), np.eye(4))
    wrist = poses["l_wrist_b0"][:3, 3]
    np.testing.assert_allclose(wrist, [0, dims.neck_shoulder_length,
                                       dims.torso_height - dims.upperarm_length - dims.forearm_length], atol=1e-5)
    assert poses["r_ankle_b0"][2, 3] == pytest.approx(-dims.thigh_length - dims.tibia_length, abs=1e-5)


def test_ros_urdf_parser_reads_the_urdf():
    urdf_parser = pytest.importorskip("urdf_parser_py.urdf")
    robot = urdf_parser.URDF.from_xml_string(human_urdf("b0", HumanDimensions.from_height(1.7)))
    movable = [j.name for j in robot.joints if j.type != "fixed"]
    assert movable == [f"{n}_b0" for n in URDF_JOINTS] or sorted(movable) == sorted(urdf_joint_names("b0"))
    assert robot.get_root() == "body_b0"
    elbow = robot.joint_map["l_elbow_b0"]
    assert (elbow.limit.lower, elbow.limit.upper) == (0.0, 2.5)


def test_with_a_straight_spine_the_posed_urdf_puts_every_joint_where_the_tracked_body_has_it(model):
    """REP-155's torso is rigid with one pitch joint: a spine that does not bend sideways or
    twist is all it can show, and then every limb joint lands on the tracked one."""
    skel = model.skeleton
    names = list(skel.joint_names)
    at = {n: k for k, n in enumerate(names)}
    for seed in range(3):
        params = _pose(model, seed)
        for k, dof in enumerate(skel.dof_names):
            if dof.startswith(("spine", "neck")):
                params[k] = 0.0
        transforms = bf.joint_transforms(model, params, model.joints_rest)
        joints, rotations = transforms[:, :3, 3], transforms[:, :3, :3] @ bf.REP155_AXES
        body = rotations[at["pelvis"]]
        dims = dimensions_from_joints(names, joints, 1.7)
        angles = dict(zip(urdf_joint_names("b0"), urdf_joint_positions(names, joints, body, rotations[at["head"]])))
        root = np.eye(4)
        root[:3, :3], root[:3, 3] = body, joints[at["pelvis"]]
        poses = _link_positions(human_urdf("b0", dims), angles, root)
        for side in "lr":
            for joint, link in (("shoulder", "y_shoulder"), ("elbow", "elbow"), ("wrist", "wrist"),
                                ("hip", "y_hip"), ("knee", "knee"), ("ankle", "ankle")):
                np.testing.assert_allclose(poses[f"{side}_{link}_b0"][:3, 3], joints[at[f"{side}_{joint}"]],
                                           atol=2e-3, err_msg=f"{side}_{joint}, seed {seed}")
