"""Tests of the gesture depth simulator: camera model agreement, Kinect noise, gesture
geometry, ground truth, bag layout and determinism (hmocap_sim.gesture_*, depth_scene)."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

from hmocap_ros.body import load_body_model
from hmocap_ros.io import topics
from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.io.conversions import camera_info_to_dict, image_to_numpy
from hmocap_ros.io.msg_factory import stamp_to_ns
from hmocap_sim import gesture_dataset as gd
from hmocap_sim import gesture_set as gs
from hmocap_sim.commands import gestures as sim_gestures
from hmocap_sim.depth_scene import (
    box,
    depth_camera,
    make_layout,
    pixel_to_optical,
    render_depth,
)
from hmocap_sim.params import DATA_DIR
from hmocap_sim.render import grid_quad

DEMO = DATA_DIR / "demo" / "gestures_depth.mcap"


@pytest.fixture(scope="module")
def model():
    return load_body_model("hands")


def _front_camera(width=320, height=240):
    return depth_camera((0.0, 1.2, 0.0), (0.0, 1.2, 5.0), width, height)


def _wall(z, half=3.0):
    """A plane facing the camera at depth z (room frame, camera at the origin, 1.2 m high)."""
    return grid_quad((-half, 1.2 - half, z), (2 * half, 0, 0), (0, 2 * half, 0), 8, 8)


# ---------------------------------------------------------------------------------------
# Depth rendering
# ---------------------------------------------------------------------------------------


def test_camera_is_kinect_like():
    cam = depth_camera((0, 1.2, 0), (0, 1.2, 3), 640, 480)
    assert (cam.width, cam.height, cam.fx, cam.fy) == (640, 480, 575.0, 575.0)
    assert cam.frame_id == "depth_optical_frame"
    assert depth_camera((0, 1.2, 0), (0, 1.2, 3), 320, 240).fx == pytest.approx(287.5)


@pytest.mark.parametrize("z", [1.0, 2.0, 3.5])
def test_plane_renders_at_its_distance(z):
    cam = _front_camera()
    r = render_depth(cam, [_wall(z)], np.random.default_rng(0))
    assert np.allclose(r.zbuf, z, atol=1e-4)  # the clean z-buffer is exact
    d = r.depth_mm[r.depth_mm > 0].astype(float) / 1000.0
    assert len(d) > 0.95 * r.depth_mm.size
    sigma = 0.0015 * z * z  # KinectNoise default: 1.5 mm at 1 m, growing as z^2
    step = z * z / (575.0 * 0.075) / 8  # 1/8 pixel disparity steps of the 640-pixel sensor
    assert abs(np.median(d) - z) < sigma + step / 2 + 0.001
    assert np.percentile(np.abs(d - z), 99) < 4 * sigma + step


def test_box_at_known_distance_projects_where_the_camera_model_says():
    cam = _front_camera()
    centre = np.array([0.3, 1.0, 2.25])
    verts, faces = box(centre, (0.4, 0.4, 0.5))  # front face at z = 2.0
    r = render_depth(cam, [(verts, faces)], np.random.default_rng(1), noise=None)
    pix, depth = cam.project(centre - [0, 0, 0.25])
    col, row = np.round(pix).astype(int)
    assert depth == pytest.approx(2.0)
    assert r.depth_mm[row, col] == 2000
    rows, cols = np.nonzero(np.abs(r.zbuf - 2.0) < 1e-4)  # the front face (a side face shows too)
    corners, _ = cam.project(np.array([[0.1, 0.8, 2.0], [0.5, 1.2, 2.0]]))
    assert cols.min() == pytest.approx(min(corners[:, 0]), abs=1.0)
    assert cols.max() == pytest.approx(max(corners[:, 0]), abs=1.0)
    assert rows.min() == pytest.approx(min(corners[:, 1]), abs=1.0)
    assert rows.max() == pytest.approx(max(corners[:, 1]), abs=1.0)
    # back-projecting a pixel with its depth gives the point on the face
    p = cam.camera_to_world(pixel_to_optical(cam, col, row, r.zbuf[row, col]))
    assert p[2] == pytest.approx(2.0, abs=1e-4)


def test_invalid_pixels_are_zero_and_noise_grows_with_distance():
    cam = _front_camera()
    rng = np.random.default_rng(2)
    near = render_depth(cam, [_wall(1.2)], rng).depth_mm
    far = render_depth(cam, [_wall(3.8)], rng).depth_mm
    beyond = render_depth(cam, [_wall(5.5)], rng).depth_mm  # outside the 4.5 m range
    empty = render_depth(cam, [box((0, 1.2, 2.0), (0.5, 0.5, 0.5))], rng).depth_mm
    assert np.all(beyond == 0)
    assert empty.dtype == np.uint16 and np.mean(empty == 0) > 0.8
    e_near = near[near > 0] / 1000.0 - 1.2
    e_far = far[far > 0] / 1000.0 - 3.8
    assert np.std(e_far) > 4 * np.std(e_near)
    # holes at the box's depth edges
    cam_box = render_depth(cam, [_wall(3.0), box((0, 1.2, 1.5), (0.5, 0.5, 0.2))], rng, noise=None)
    noisy = render_depth(cam, [_wall(3.0), box((0, 1.2, 1.5), (0.5, 0.5, 0.2))], rng).depth_mm
    edge = np.abs(np.diff(cam_box.zbuf, axis=1)) > 0.5
    edge_pixels = noisy[:, 1:][edge]
    assert np.mean(edge_pixels == 0) > 0.3


def test_layouts_keep_the_person_zone_and_corridor_free():
    for i in range(6):
        lay = make_layout(np.random.default_rng([7, i]), i)
        x0, z0, r = lay.zone
        assert 1.5 <= z0 - r and z0 + r <= 3.5
        for _, x, z, _ in lay.items:
            assert np.hypot(x - x0, z - z0) > r
        assert 1.0 <= lay.camera.position[1] <= 1.5
        assert abs(lay.camera.optical_axis[1]) < np.sin(np.deg2rad(15))  # roughly horizontal


# ---------------------------------------------------------------------------------------
# Gesture poses
# ---------------------------------------------------------------------------------------


def test_class_list_is_fixed():
    assert gs.GESTURE_CLASSES == ("tee", "pause", "silence", "cross", "ok", "volume_up")
    assert gs.ALL_GESTURES == gs.GESTURE_CLASSES + gs.NEW_GESTURES == gs.GESTURE_CLASSES + ("thumbs_up", "raised_fist")
    assert [gs.class_id(n) for n in gs.ALL_GESTURES] == [1, 2, 3, 4, 5, 6, 7, 8]
    assert set(gs.REFERENCE_POINTS) == set(gs.ALL_GESTURES)
    assert tuple(gs.GESTURES) == gs.ALL_GESTURES  # one builder per class, in class-id order
    assert tuple(gs.NEGATIVE_BUILDERS) == gs.NEGATIVE_KINDS == tuple(gs.NEGATIVE_WEIGHTS)
    assert tuple(gs.NEAR_MISS_BUILDERS) == gs.NEAR_MISS_KINDS
    assert set(gs.NEAR_MISSES.values()) == set(gs.ALL_GESTURES)  # every gesture has near misses
    assert not set(gs.NEAR_MISS_KINDS) & (set(gs.NEGATIVE_KINDS) | set(gs.ALL_GESTURES))


def test_subject_identity_depends_on_the_id_only(model):
    a, b, c = gs.make_subject(model, 3), gs.make_subject(model, 3), gs.make_subject(model, 4)
    assert np.array_equal(a.shape.to_vector(), b.shape.to_vector())
    assert not np.allclose(a.shape.to_vector(), c.shape.to_vector())
    assert 1.4 < a.height < 2.0


def _solve(model, name, k):
    rng = np.random.default_rng([11, k])
    subj = gs.make_subject(model, k)
    camera = np.array([rng.uniform(-0.8, 0.8), rng.uniform(1.0, 1.5), rng.uniform(1.5, 3.5)])
    spec = gs.gesture_spec(model, subj, name, rng, camera_body=camera)
    params = gs.solve_spec(model, subj, spec)
    return subj, spec, params, gs.kinematics(model, subj, params), camera


@pytest.mark.parametrize("k", [0, 1, 2])
@pytest.mark.parametrize("name", gs.ALL_GESTURES)
def test_gesture_geometry(model, name, k):
    subj, spec, params, kin, camera = _solve(model, name, k)

    def P(n):
        return kin.point(model, n)[0]

    s = spec.side
    assert s in ("l", "r") and spec.class_id == gs.class_id(name)
    if name == "silence":
        assert np.linalg.norm(P(f"{s}_index_tip") - P("mouth")) < 0.05
        d = P(f"{s}_index_tip") - P(f"{s}_index1")
        assert d[1] / np.linalg.norm(d) > 0.8  # the finger is upright
        curled = np.linalg.norm(P(f"{s}_ring_tip") - P(f"{s}_palm"))
        assert curled < 0.06  # other fingers curled into the palm
    elif name == "ok":
        assert np.linalg.norm(P(f"{s}_thumb_tip") - P(f"{s}_index_tip")) < 0.03
        assert np.linalg.norm(P(f"{s}_hand_tip") - P(f"{s}_palm")) > 0.08  # middle finger extended
        assert np.linalg.norm(P(f"{s}_pinky_tip") - P(f"{s}_palm")) > 0.06
    elif name == "pause":
        _, _, volar = gs.hand_axes(model, kin, s)
        to_cam = camera - P(f"{s}_palm")
        assert volar[0] @ to_cam / np.linalg.norm(to_cam) > 0.7  # palm towards the camera
        assert P(f"{s}_palm")[1] > P(f"{s}_shoulder")[1]  # arm raised
        assert np.linalg.norm(P(f"{s}_hand_tip") - P(f"{s}_palm")) > 0.08  # open hand
    elif name == "cross":
        c = gs.forearm_crossing(kin, model)[0]
        l_axis = gs.closest_on_segments(c[None], P("l_elbow")[None], P("l_wrist")[None])[0]
        r_axis = gs.closest_on_segments(c[None], P("r_elbow")[None], P("r_wrist")[None])[0]
        assert np.linalg.norm(l_axis - r_axis) < 0.12  # the forearms touch (axes ~8 cm apart)
        assert (c - P("sternum"))[2] > 0.05  # in front of the chest
        assert P("spine")[1] < c[1] < P("neck")[1] + 0.05
        assert (P("l_wrist") - P("l_elbow"))[0] < 0 < (P("r_wrist") - P("r_elbow"))[0]  # crossed
    elif name == "volume_up":
        assert np.linalg.norm(P(f"{s}_palm") - P(f"{s}_ear")) < 0.1
        assert np.linalg.norm(P(f"{s}_hand_tip") - P(f"{s}_ear")) < 0.2
    elif name == "tee":
        o = gs.other(s)
        assert np.linalg.norm(P(f"{s}_hand_tip") - P(f"{o}_palm")) < 0.04  # fingertips on the palm
        d_s, _, _ = gs.hand_axes(model, kin, s)
        d_o, _, v_o = gs.hand_axes(model, kin, o)
        assert abs(d_s[0] @ d_o[0]) < 0.5  # a T: the hands are roughly perpendicular
        assert d_s[0][1] > 0.6 and v_o[0][1] < -0.8  # stem upright, top palm down
        assert (P(f"{s}_hand_tip") - P("sternum"))[2] > 0.1  # in front of the chest
    elif name == "thumbs_up":
        thumb = P(f"{s}_thumb_tip") - P(f"{s}_thumb2")
        assert thumb[1] / np.linalg.norm(thumb) > 0.7  # the thumb points up
        assert np.linalg.norm(P(f"{s}_index_tip") - P(f"{s}_palm")) < 0.07  # the other fingers curled
        assert (P(f"{s}_palm") - P("sternum"))[2] > 0.05  # in front of the body
    elif name == "raised_fist":
        assert P(f"{s}_palm")[1] > P(f"{s}_shoulder")[1] + 0.2  # raised above the shoulder
        assert np.linalg.norm(P(f"{s}_hand_tip") - P(f"{s}_palm")) < 0.07  # a fist
    # the annotated point is on the upper body, not behind it
    ref = gs.reference_point(model, kin, name, s)[0]
    assert (ref - P("pelvis"))[2] > -0.08 and np.linalg.norm(ref - P("chest")) < 0.7


@pytest.mark.parametrize("kind", gs.NEGATIVE_KINDS)
def test_negative_poses_are_not_gestures(model, kind):
    rng = np.random.default_rng([5, gs.NEGATIVE_KINDS.index(kind)])
    subj = gs.make_subject(model, 9)
    spec = gs.negative_spec(model, subj, kind, rng, camera_body=np.array([0.0, 1.2, 2.5]))
    assert spec.class_id == 0
    params = gs.solve_spec(model, subj, spec)
    assert np.all(np.isfinite(params))
    kin = gs.kinematics(model, subj, params)
    for s in gs.SIDES:  # no finger on the lips: silence stays a gesture of its own
        assert np.linalg.norm(kin.point(model, f"{s}_index_tip")[0] - kin.point(model, "mouth")[0]) > 0.03


def _near_miss(model, kind, k=0):
    rng = np.random.default_rng([6, gs.NEAR_MISS_KINDS.index(kind), k])
    subj = gs.make_subject(model, 9 + k)
    spec = gs.pose_spec(model, subj, kind, rng, camera_body=np.array([0.0, 1.2, 2.5]))
    params = gs.solve_spec(model, subj, spec)
    return spec, gs.kinematics(model, subj, params)


@pytest.mark.parametrize("k", [0, 1])
@pytest.mark.parametrize("kind", gs.NEAR_MISS_KINDS)
def test_near_misses_are_their_gesture_done_wrong(model, kind, k):
    """A near miss is background and differs from its gesture in what its table says."""
    spec, kin = _near_miss(model, kind, k)

    def P(n):
        return kin.point(model, n)[0]

    s, o = spec.side, gs.other(spec.side)
    assert spec.class_id == 0 and spec.kind == kind

    def gap(a, b):
        return float(np.linalg.norm(P(a) - P(b)))

    d, _, volar = (x[0] for x in gs.hand_axes(model, kin, s))
    checks = {
        "tee_apart": gap(f"{s}_hand_tip", f"{o}_palm") > 0.06,
        "tee_fist": gap(f"{o}_hand_tip", f"{o}_palm") < 0.07,
        "pause_curled": gap(f"{s}_hand_tip", f"{s}_palm") < 0.08,
        "pause_one_bent": min(gap(f"{s}_{f}_tip", f"{s}_palm") for f in ("index", "hand", "ring", "pinky")) < 0.07,
        "pause_together": gap(f"{s}_index_tip", f"{s}_pinky_tip") < 1.65 * gap(f"{s}_index1", f"{s}_pinky1"),
        "pause_tilted": abs(volar[1]) > 0.5,  # the palm faces up or down, not the camera
        "pause_sideways": abs(d[1]) < 0.6,
        "pause_half": P(f"{s}_palm")[1] < P(f"{s}_shoulder")[1] - 0.05,
        "silence_cheek": gap(f"{s}_index_tip", "mouth") > 0.035,
        "silence_bent": gap(f"{s}_index_tip", f"{s}_palm") < 0.07,
        "cross_apart": P("l_wrist")[0] > P("r_wrist")[0] + 0.1,  # each wrist on its own side
        "cross_one": P(f"{o}_wrist")[1] < P("sternum")[1] - 0.2,  # the other arm down
        "ok_open": gap(f"{s}_thumb_tip", f"{s}_index_tip") > 0.03,
        "ok_closed": gap(f"{s}_pinky_tip", f"{s}_palm") < 0.06,
        "volume_low": gap(f"{s}_palm", f"{s}_ear") > 0.08,
        "volume_flat": gap(f"{s}_hand_tip", f"{s}_palm") > 0.08,
        "thumbs_sideways": (P(f"{s}_thumb_tip") - P(f"{s}_thumb2"))[1] / gap(f"{s}_thumb_tip", f"{s}_thumb2") < 0.6,
        "thumbs_tucked": (P(f"{s}_thumb_tip") - P(f"{s}_palm"))[1] < 0.05,  # not above the fist
        "raised_fist_half": P(f"{s}_palm")[1] < P(f"{s}_shoulder")[1],
        "raised_open": gap(f"{s}_hand_tip", f"{s}_palm") > 0.08,
    }
    assert set(checks) == set(gs.NEAR_MISS_KINDS)
    assert checks[kind], kind


def test_occluded_reference_is_marked_invalid(model):
    rng = np.random.default_rng(3)
    lay = make_layout(np.random.default_rng(4), 0, 320, 240, n_bystanders=0)
    actor = gd.Actor(gs.make_subject(model, 1))
    x, z = lay.zone[:2]
    yaw = gd.facing_yaw(lay.camera.position, x, z)
    spec = gs.gesture_spec(model, actor.subject, "pause", rng,
                           camera_body=gs.world_to_body(x, z, yaw, lay.camera.position))
    actor.params = gs.place(model, gs.solve_spec(model, actor.subject, spec), x, z, yaw)
    state = gd.FrameState(actor.params, "hold", "pause", spec.side, 0)
    palm = gs.reference_point(model, gs.kinematics(model, actor.subject, actor.params), "pause", spec.side)[0]
    occluder = box(0.6 * palm + 0.4 * lay.camera.position, (0.25, 0.25, 0.05))
    for blocked in (False, True):
        meshes = [(lay.vertices, lay.faces), (actor.vertices(model), model.faces)] + ([occluder] if blocked else [])
        r = render_depth(lay.camera, meshes, rng)
        face_range = (int(r.face_offsets[1]), int(r.face_offsets[2]))
        gt = gd.ground_truth(model, actor, state, lay, r, face_range)
        assert gt.class_id == gs.class_id("pause")
        assert gt.visible is (not blocked)
        pix, depth = lay.camera.project(palm)
        assert (gt.u, gt.v) == pytest.approx(tuple(pix))
        if not blocked:  # the surface point at (u, v): the palm, a little in front of its centre
            assert 0 < depth - gt.position[2] < 0.05


# ---------------------------------------------------------------------------------------
# Bags
# ---------------------------------------------------------------------------------------


def _generate(out, **kw):
    args = dict(seed=3, subjects=2, frames=36, width=160, height=120, hold=(2, 4), progress=False)
    args.update(kw)
    return gd.generate(out, **args)


@pytest.fixture(scope="module")
def small_bag(tmp_path_factory):
    out = tmp_path_factory.mktemp("gestures") / "set.mcap"
    summary = _generate(out, subject_offset=40)
    return out, summary


def _read(bag):
    frames = {}
    with BagReader(bag) as reader:
        info = reader.topics()
        for m in reader.messages():
            stamp = stamp_to_ns(m.msg.header.stamp)
            assert m.log_time_ns == stamp  # bag log time = stamp
            assert m.msg.header.frame_id == "depth_optical_frame"
            frames.setdefault(stamp, {})[m.topic] = m.msg
    return info, frames


def _check_bag(bag):
    info, frames = _read(bag)
    labels_path, _ = gd.sidecar_paths(bag)
    labels = json.loads(labels_path.read_text())
    assert info[topics.DEPTH_IMAGE].msgtype == "sensor_msgs/msg/Image"
    assert info[topics.DEPTH_INFO].msgtype == "sensor_msgs/msg/CameraInfo"
    assert info[topics.GT_GESTURES].msgtype == "hmocap_interfaces/msg/GestureArray"
    with_near = topics.GT_NEAR_MISSES in info  # the shipped demo bag was made without it
    if with_near:
        assert info[topics.GT_NEAR_MISSES].msgtype == "hmocap_interfaces/msg/GestureArray"
    assert len(frames) == len(labels["frames"])
    assert all(len(f) == 3 + with_near for f in frames.values())  # every frame has every topic
    stamps = sorted(frames)
    assert stamps == [f["stamp_ns"] for f in labels["frames"]]
    assert np.all(np.diff(stamps) > 0)
    checked = 0
    for record in labels["frames"]:
        f = frames[record["stamp_ns"]]
        image = f[topics.DEPTH_IMAGE]
        assert image.encoding == "16UC1"
        depth = image_to_numpy(image)
        cam = camera_info_to_dict(f[topics.DEPTH_INFO])
        K = cam["K"]
        gestures = f[topics.GT_GESTURES].gestures
        assert len(gestures) == (1 if record["class_id"] else 0)
        near = f[topics.GT_NEAR_MISSES].gestures if with_near else []
        is_near = record["kind"] in gs.NEAR_MISSES and record["phase"] == "negative"
        assert not with_near or len(near) == int(is_near)
        if near:  # a near miss: its kind, the class it misses, that gesture's reference pixel
            assert near[0].name == record["kind"] and gestures == []
            assert gs.GESTURE_CLASSES[near[0].class_id - 1] == gs.NEAR_MISSES[record["kind"]]
        if not gestures:
            continue
        g = gestures[0]
        assert (g.class_id, g.name) == (record["class_id"], record["name"])
        assert g.name == gs.GESTURE_CLASSES[g.class_id - 1] and g.score == 1.0 and g.volume == 1.0
        assert g.position_valid == record["visible"]
        assert (g.u, g.v) == pytest.approx((record["u"], record["v"]), abs=1e-3)
        # back-projecting (u, v) with the GT depth gives the GT position
        xyz = np.array([g.position.x, g.position.y, g.position.z])
        ray = np.array([(g.u - K[0, 2]) / K[0, 0], (g.v - K[1, 2]) / K[1, 1], 1.0])
        assert np.allclose(ray * g.position.z, xyz, atol=1e-4)
        if g.position_valid:  # (u, v) lies on the person: the measured depth there is the GT depth
            measured = depth[int(round(g.v)), int(round(g.u))] / 1000.0
            if measured > 0:  # not a hole
                assert abs(measured - g.position.z) < 0.01 + 0.006 * g.position.z ** 2
                checked += 1
    return labels, checked


def test_bag_layout_and_ground_truth(small_bag):
    out, summary = small_bag
    labels, checked = _check_bag(out)
    assert summary.frames == 36 and checked >= 5
    assert topics.GT_NEAR_MISSES in _read(out)[0]
    assert labels["format"] == gd.LABELS_FORMAT
    assert labels["classes"] == {str(i + 1): n for i, n in enumerate(gs.GESTURE_CLASSES)}
    assert sorted({f["subject"] for f in labels["frames"]}) == [40, 41]
    assert set(labels["subjects"]) == {"40", "41"}
    assert {f["phase"] for f in labels["frames"]} <= {"hold", "negative", "transition"}
    assert all(1.3 < f["distance_m"] < 3.7 for f in labels["frames"])
    assert gd.sidecar_paths(out)[1].stat().st_size > 1000  # the contact sheet
    assert 0 < sum(f["class_id"] == 0 for f in labels["frames"]) < 36


def test_near_miss_frames_carry_where_the_near_miss_is(tmp_path):
    """A bag of near misses: each hold frame says which gesture it misses and where (the pixel of
    that gesture's reference point), and training reads those frames as located background."""
    from hmocap_ros.eval.gesture_training_bags import read_training_bags

    out = tmp_path / "near.mcap"
    _generate(out, subject_offset=60, frames=30, gestures=(), negatives=0, near_misses=6,
              near_of=gs.GESTURE_CLASSES, contact=False)
    labels, _ = _check_bag(out)
    near = [f for f in labels["frames"] if f["phase"] == "negative"]
    assert len(near) >= 15 and all(f["kind"] in gs.NEAR_MISSES for f in near)
    data, _ = read_training_bags([out])
    located = [lab for lab in data.labels if lab is not None]
    assert len(located) == sum(m is not None for m in data.near_misses) >= 10
    assert all(lab[0] == 0 and 0 <= lab[1] < 160 and 0 <= lab[2] < 120 for lab in located)


def test_same_seed_same_bytes(tmp_path, small_bag):
    a, b, c = tmp_path / "a" / "set.mcap", tmp_path / "b" / "set.mcap", tmp_path / "c" / "set.mcap"
    for out, seed in ((a, 3), (b, 3), (c, 4)):
        out.parent.mkdir()
        _generate(out, seed=seed, frames=8, contact=False)
    assert a.read_bytes() == b.read_bytes()
    assert a.read_bytes() != c.read_bytes()
    assert gd.sidecar_paths(a)[0].read_text() == gd.sidecar_paths(b)[0].read_text()


def test_cli_refuses_to_overwrite(tmp_path, capsys):
    parser = argparse.ArgumentParser()
    sim_gestures.add_arguments(parser)
    out = tmp_path / "g.mcap"
    out.write_bytes(b"x")
    assert sim_gestures.main_from_args(parser.parse_args(["--out", str(out)])) == 2
    assert "exists" in capsys.readouterr().err
    ns = parser.parse_args(["--out", str(out), "--force", "--frames", "3", "--width", "64", "--height", "48",
                            "--quiet", "--no-contact-sheet", "--subjects", "1"])
    assert sim_gestures.main_from_args(ns) == 0
    assert gd.sidecar_paths(out)[0].exists() and not gd.sidecar_paths(out)[1].exists()


def test_shipped_demo_bag():
    assert DEMO.is_file(), f"{DEMO} is missing: the gesture bag is shipped with the package"
    labels, checked = _check_bag(DEMO)
    names = {f["name"] for f in labels["frames"] if f["visible"]}
    assert names == set(gs.GESTURE_CLASSES)
    assert sum(f["class_id"] == 0 for f in labels["frames"]) >= 10
    assert checked >= 20
    assert DEMO.stat().st_size < 2.5e6
    assert gd.sidecar_paths(DEMO)[1].exists()
