"""Multi-view simulator: bag layout, exact ground truth, determinism, rig options.

Everything renders at tiny resolutions and for a handful of frames, so the whole file runs in
seconds once numba's kernels are compiled (cached on disk after the first run).
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from hmocap_ros.body import BodyShape, load_body_model
from hmocap_ros.geometry import project_points
from hmocap_ros.geometry.projection import project_batch
from hmocap_ros.geometry.rig import load_rig
from hmocap_ros.io import topics
from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.io.conversions import image_to_numpy, joint_state_to_dict
from hmocap_ros.io.msg_factory import stamp_to_ns
from hmocap_ros.io.rig_messages import rig_from_msg
from hmocap_ros.render.silhouette import render_silhouettes
from hmocap_sim import mocap_lighting, mocap_subject
from hmocap_sim.appearance import PersonAppearance, dress, sample_appearance
from hmocap_sim.mocap_dataset import MocapSimConfig, generate, make_rig
from hmocap_sim.mocap_render import (
    FrameState,
    MocapRenderer,
    RenderOptions,
    camera_arrays,
)
from hmocap_sim.params import DATA_DIR
from hmocap_sim.room import build_room

N_BG, N_MOTION = 2, 6


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "run.mcap"
    cfg = MocapSimConfig(out=out, width=160, height=120, start=2.0, seconds=N_MOTION / 25,
                         background_seconds=N_BG / 25, seed=5, contact_frames=2,
                         progress=False)
    return generate(cfg)


@pytest.fixture(scope="module")
def bag_data(recording):
    """Everything in the recording's bag, grouped by topic: [(stamp, log_time, msg)]."""
    data = {}
    with BagReader(recording.bag) as reader:
        info = reader.topics()
        for m in reader.messages():
            data.setdefault(m.topic, []).append((stamp_to_ns(m.msg.header.stamp),
                                                 m.log_time_ns, m.msg))
    return info, data


@pytest.fixture(scope="module")
def models():
    return load_body_model("tracking"), load_body_model("hands", "full")


def test_bag_has_the_documented_layout(recording, bag_data):
    info, data = bag_data
    rig = make_rig(4, 160, 120)
    n = N_BG + N_MOTION
    expected = {topics.CAMERA_RIG: ("hmocap_interfaces/msg/CameraRig", 1, True),
                topics.GT_BODY_SHAPE: ("hmocap_interfaces/msg/BodyShape", 1, True),
                topics.GT_SKELETON: ("hmocap_interfaces/msg/Skeleton", N_MOTION, False),
                topics.GT_JOINT_STATES: ("sensor_msgs/msg/JointState", N_MOTION, False)}
    for cam in rig.names:
        expected[topics.camera_image(cam)] = ("sensor_msgs/msg/Image", n, False)
        expected[topics.gt_silhouette(cam)] = ("sensor_msgs/msg/Image", n, False)
    assert set(info) == set(expected)
    for topic, (msgtype, count, latched) in expected.items():
        assert (info[topic].msgtype, info[topic].count, info[topic].latched) == (msgtype, count,
                                                                                  latched), topic
    # One stamp per frame, shared by every message of the frame and equal to the log time.
    stamps = list(recording.stamps_ns)
    assert len(stamps) == n and np.all(np.diff(stamps) == 40_000_000)
    for topic, items in data.items():
        assert all(s == log for s, log, _ in items), topic
        got = [s for s, _, _ in items]
        if topic in (topics.CAMERA_RIG, topics.GT_BODY_SHAPE):
            assert got == stamps[:1]
        elif topic in (topics.GT_SKELETON, topics.GT_JOINT_STATES):
            assert got == stamps[N_BG:]
        else:
            assert got == stamps
    for cam in rig:
        img = data[topics.camera_image(cam.name)][0][2]
        sil = data[topics.gt_silhouette(cam.name)][0][2]
        assert (img.encoding, img.width, img.height) == ("rgb8", 160, 120)
        assert (sil.encoding, sil.width, sil.height) == ("mono8", 160, 120)
        assert img.header.frame_id == sil.header.frame_id == cam.frame_id
    assert data[topics.GT_SKELETON][0][2].header.frame_id == "room"
    # Silhouettes: empty before the subject appears, 0/255 and non-empty afterwards.
    for cam in rig.names:
        masks = [image_to_numpy(m) for _, _, m in data[topics.gt_silhouette(cam)]]
        assert all(not m.any() for m in masks[:N_BG])
        assert all(set(np.unique(m)) == {0, 255} for m in masks[N_BG:])


def test_rig_yaml_matches_the_bag(recording, bag_data):
    _, data = bag_data
    from_bag = rig_from_msg(data[topics.CAMERA_RIG][0][2])
    assert load_rig(recording.rig_yaml).isclose(from_bag, atol=1e-6)
    assert from_bag.isclose(make_rig(4, 160, 120), atol=1e-6)
    sheet = cv2.imread(str(recording.contact_sheet))
    assert sheet is not None and sheet.shape[0] > 200 and sheet.shape[1] > 4 * 320


def _frames(data, rig):
    """Per motion frame: (skeleton points (P, 3), parents, {cam: silhouette})."""
    masks = {cam: {s: image_to_numpy(m) for s, _, m in data[topics.gt_silhouette(cam)]}
             for cam in rig.names}
    for stamp, _, skel in data[topics.GT_SKELETON]:
        pts = np.array([[p.x, p.y, p.z] for p in skel.positions])
        yield stamp, pts, list(skel.joint_names), {c: masks[c][stamp] for c in rig.names}


def test_joints_project_inside_the_silhouettes(bag_data, models):
    _, data = bag_data
    tracking, _ = models
    rig = rig_from_msg(data[topics.CAMERA_RIG][0][2])
    kernel = np.ones((5, 5), np.uint8)  # 2-pixel dilation for joints on a 1-pixel-wide limb
    for _, pts, names, masks in _frames(data, rig):
        assert names[:19] == list(tracking.joint_names)
        assert names[19:] == list(tracking.end_site_names)
        proj = project_points(rig.cameras, pts[:19])
        for k, cam in enumerate(rig.names):
            assert proj.visible[k].all()
            mask = cv2.dilate(masks[cam], kernel)
            uv = np.round(proj.pixels[k]).astype(int)
            inside = mask[uv[:, 1], uv[:, 0]] > 0
            assert inside.all(), (cam, [n for n, ok in zip(names, inside) if not ok])


def test_joint_states_and_body_shape_reproduce_the_skeleton(bag_data, models):
    _, data = bag_data
    tracking, _ = models
    msg = data[topics.GT_BODY_SHAPE][0][2]
    shape = BodyShape(np.asarray(msg.bone_scale, float), np.asarray(msg.radial_scale, float),
                      float(msg.global_scale), tuple(msg.entity_names))
    assert msg.height == pytest.approx(float(shape.height(tracking)), abs=1e-3)
    assert 1.4 < msg.height < 2.05
    for (_, _, js), (_, _, skel) in zip(data[topics.GT_JOINT_STATES], data[topics.GT_SKELETON]):
        d = joint_state_to_dict(js)
        assert d["name"] == list(tracking.skeleton.dof_names)
        res = tracking.forward(d["position"][None], shape)
        pts = np.array([[p.x, p.y, p.z] for p in skel.positions])
        np.testing.assert_allclose(res.joints[0], pts[:19], atol=1e-4)
        np.testing.assert_allclose(res.end_sites[0], pts[19:], atol=1e-4)
        assert res.vertices[0][:, 1].min() > -0.06  # feet on (not through) the floor


def test_silhouettes_match_the_tracking_body_posed_from_ground_truth(bag_data, models):
    """The tracker's own (coarser) body posed with the ground truth covers the silhouette."""
    _, data = bag_data
    tracking, _ = models
    rig = rig_from_msg(data[topics.CAMERA_RIG][0][2])
    K, R, t, dist = camera_arrays(rig)
    msg = data[topics.GT_BODY_SHAPE][0][2]
    shape = BodyShape(np.asarray(msg.bone_scale, float), np.asarray(msg.radial_scale, float),
                      float(msg.global_scale))
    for (_, _, js), (stamp, _, _) in zip(data[topics.GT_JOINT_STATES], data[topics.GT_SKELETON]):
        verts = tracking.forward(joint_state_to_dict(js)["position"][None], shape).vertices
        uv, _ = project_batch(verts.astype(np.float64), K, R, t, dist)
        model = render_silhouettes(uv[0], tracking.faces, 120, 160)
        for k, cam in enumerate(rig.names):
            gt = [image_to_numpy(m) for s, _, m in data[topics.gt_silhouette(cam)] if s == stamp][0]
            a, b = model[k] > 0, gt > 0
            assert (a & b).sum() / (a | b).sum() > 0.88  # 0.94-0.97 on this recording


def _renderer_scene(seed=0, width=160, height=120, second=False):
    rng = np.random.default_rng(seed)
    rig = make_rig(4, width, height)
    room = build_room(rng)
    full = load_body_model("hands", "full")
    look = dress(full, sample_appearance(rng))
    people = [(full.faces, look)] + ([(full.faces, dress(full, PersonAppearance()))]
                                     if second else [])
    renderer = MocapRenderer(rig, room, people, RenderOptions(noise=False))
    params = full.rest_pose()[None].repeat(2, 0)
    params[:, full.skeleton.dof_index("l_shoulder_abd")] = 0.6
    params[:, full.skeleton.dof_index("r_elbow_flex")] = 1.0
    params[1, [0, 2]] = (-1.0, 0.85)  # the second person, between cam_4 and the first
    verts = full.forward(params).vertices
    return rig, renderer, full, look, verts


def test_silhouette_is_the_independent_rasterisation_when_unoccluded():
    rig, renderer, full, look, verts = _renderer_scene()
    subject = look.with_hair(verts[0], full.faces)
    frame = renderer.render(FrameState(people=(subject,)))
    uv, _ = project_batch(subject[None].astype(np.float64), *camera_arrays(rig))
    expected = render_silhouettes(uv[0], full.faces, 120, 160)
    for k in range(len(rig)):
        a, b = frame.silhouettes[k] > 0, expected[k] > 0
        assert b.sum() > 200
        assert (a & b).sum() / (a | b).sum() > 0.97
        assert frame.images[k].shape == (120, 160, 3) and frame.images[k].dtype == np.uint8


def test_silhouette_excludes_what_occludes_the_subject():
    rig, renderer, full, look, verts = _renderer_scene(second=True)
    subject = look.with_hair(verts[0], full.faces)
    alone = renderer.render(FrameState(people=(subject, None)))
    both = renderer.render(FrameState(people=(subject, verts[1])))
    lost = [(a > 0).sum() - (b > 0).sum() for a, b in zip(alone.silhouettes, both.silhouettes)]
    for a, b in zip(alone.silhouettes, both.silhouettes):
        assert not np.any((b > 0) & (a == 0))  # occlusion only removes pixels
    assert max(lost) > 50  # the second person hides part of the subject in some view


def test_posed_body_stays_watertight(models):
    tracking, full = models
    look = dress(full, PersonAppearance(long_hair=True))
    faces = np.asarray(full.faces)
    rng = np.random.default_rng(1)
    from hmocap_ros.body import sample_pose, sample_shape

    params = sample_pose(tracking.skeleton, rng, 3, scale=0.6)
    full_params = mocap_subject.full_parameters(params, tracking, full)
    shape = sample_shape(rng)
    res = full.forward(full_params, shape)
    # The finer rendered body and the tracking body share their joints exactly.
    np.testing.assert_allclose(res.joints[:, :19], tracking.forward(params, shape).joints,
                               atol=1e-9)
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)  # closed 2-manifold: every edge has exactly two faces
    v_count = len(np.unique(faces))
    assert v_count - len(counts) + len(faces) == 2  # Euler characteristic of a sphere

    def volume(v):
        a, b, c = (v[faces[:, i]].astype(np.float64) for i in range(3))
        return np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0

    rest = volume(full.forward(full.rest_pose()[None], shape).vertices[0])
    for v in res.vertices:
        v = look.with_hair(v, faces)
        assert np.isfinite(v).all()
        assert volume(v) == pytest.approx(rest, rel=0.12)  # outward, not folded inside out


def test_same_seed_same_bytes_and_other_options(tmp_path):
    def run(name, seed, **kw):
        cfg = MocapSimConfig(out=tmp_path / f"{name}.mcap", seconds=0.08, background_seconds=0.0,
                             seed=seed, contact_frames=1, progress=False, **kw)
        result = generate(cfg)
        with BagReader(result.bag) as reader:
            imgs = [bytes(m.msg.data) for m in reader.messages()
                    if m.topic.endswith("/image_raw")]
            n_cams = len([t for t in reader.topics() if t.endswith("/image_raw")])
            size = reader.first(topics.camera_image("cam_1"))
            skel = [[(p.x, p.y, p.z) for p in m.msg.positions]
                    for m in reader.messages([topics.GT_SKELETON])]
        return imgs, n_cams, (size.width, size.height), result, skel

    base = dict(cameras=3, width=96, height=72)
    a, n_cams, size, result, skel_a = run("a", 11, **base)
    b, _, _, _, skel_b = run("b", 11, **base)
    c, _, _, _, skel_c = run("c", 12, **base)
    assert a == b and skel_a == skel_b
    assert all(x != y for x, y in zip(a, c)) and skel_a != skel_c
    assert n_cams == 3 and size == (96, 72) and result.n_frames == 2
    # Distractors only add things: the subject and its ground truth keep their seed.
    d, _, _, _, skel_d = run("d", 11, distractors=True, **base)
    assert len(d) == len(a) and skel_d == skel_a
    # So do lighting changes (their own random stream).
    e, _, _, _, skel_e = run("e", 11, lighting_changes=True, **base)
    assert len(e) == len(a) and skel_e == skel_a


def test_still_seconds_hold_the_first_pose_in_view_from_the_first_frame(tmp_path):
    """``--still-seconds`` with ``--background-seconds 0``: the subject is there in the first
    frame and stands in the motion's first pose, then moves as without the option."""
    def skeletons(name, still):
        cfg = MocapSimConfig(out=tmp_path / f"{name}.mcap", cameras=2, width=64, height=48,
                             seconds=0.12, background_seconds=0.0, still_seconds=still, seed=7,
                             contact_frames=0, progress=False, noise=False, shadows=False)
        generate(cfg)
        with BagReader(cfg.out) as reader:
            first_image = reader.first(topics.camera_image("cam_1")).header.stamp
            joints = [np.array([(p.x, p.y, p.z) for p in m.msg.positions])
                      for m in reader.messages([topics.GT_SKELETON])]
            first_truth = reader.first(topics.GT_SKELETON).header.stamp
            silhouette = reader.first(topics.gt_silhouette("cam_1"))
        assert first_truth == first_image and np.frombuffer(silhouette.data, np.uint8).any()
        return np.stack(joints)

    moving = skeletons("moving", 0.0)
    held = skeletons("held", 0.08)
    assert len(moving) == 3 and len(held) == 5
    np.testing.assert_allclose(held[1], held[0]) and np.testing.assert_allclose(held[2], held[0])
    assert np.abs(moving[2] - moving[0]).max() > 1e-3  # the motion does move ...
    # ... and is the same after the hold (up to where the subject is placed and how its feet are
    # levelled over the clip: a few millimetres)
    np.testing.assert_allclose(held[2:] - held[2:, :1], moving - moving[:, :1], atol=2e-3)


def test_lighting_events_dim_the_lamp_and_come_back():
    t = np.arange(150) / 25.0
    lamp, exposure, window = mocap_lighting.lighting_events(np.random.default_rng(3), t, 1.0, 6.0)
    assert lamp[0] == 1.0 and lamp[-1] == 1.0 and 0.25 <= lamp.min() <= 0.35
    dim = np.flatnonzero(lamp < 0.5)
    assert 1.0 + 0.2 * 5 <= t[dim[0]] <= 1.0 + 0.31 * 5 and t[dim[-1]] <= 1.0 + 0.71 * 5
    # the auto-exposure answers late and only in part
    assert exposure[dim[0]] < exposure[dim[-1]] < 1.3 and exposure.min() == pytest.approx(1.0)
    assert 0.6 < window.min() < 0.7 and window[0] > 0.99


def test_make_rig_options():
    example = make_rig(4, 640, 480)
    small = make_rig(4, 320, 240)
    assert small.isclose(example.scaled(0.5))
    for n in (1, 3, 6, 8):
        rig = make_rig(n, 320, 180)
        assert len(rig) == n and all((c.width, c.height) == (320, 180) for c in rig)
        centre = project_points(rig.cameras, np.array([[0.0, 1.0, 0.0]])).pixels[:, 0]
        assert np.all(np.abs(centre - [159.5, 89.5]) < 5.0)
        for cam in rig:
            x, y, z = cam.position
            assert y == pytest.approx(2.5) and abs(x) <= 2.8 + 1e-9 and abs(z) <= 2.3 + 1e-9
    assert make_rig(8, 64, 48)[0].fx == pytest.approx(0.8125 * 64, rel=0.02)
    with pytest.raises(ValueError):
        make_rig(9, 640, 480)


def test_cli(tmp_path, capsys):
    from hmocap_ros.cli import main

    out = tmp_path / "cli.mcap"
    args = ["sim", "mocap", "--out", str(out), "--cameras", "2", "--width", "64", "--height",
            "48", "--seconds", "0.04", "--background-seconds", "0", "--quiet", "--no-shadow",
            "--contact-frames", "1"]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "1 frames" in text and "2 cameras 64x48" in text and "s per frame" in text
    assert out.is_file() and (tmp_path / "cli_rig.yaml").is_file()
    assert (tmp_path / "cli.contact.png").is_file()
    assert main(args) == 2  # refuses to overwrite without --force
    assert main(args + ["--force"]) == 0
    assert math.isfinite(out.stat().st_size)


def test_a_run_too_long_for_the_views_stays_inside_the_room(capsys):
    """The 4 m of the shipped run cannot stay in every view of the room: the placement keeps
    the pelvis ``MIN_PELVIS_CLEARANCE`` from walls and furniture in every frame, and says that
    the motion leaves some view."""
    cfg = MocapSimConfig(out="unused.mcap", bvh=DATA_DIR / "bvh" / "09_01.bvh",
                         start=0.0, seconds=1.2, seed=204, progress=False)
    rng_room, rng_shape, _, rng_place = mocap_subject.random_streams(cfg.seed)[:4]
    _, room, _, _, motion = mocap_subject.subject_in_room(cfg, rng_room, rng_shape, rng_place)
    root = motion.root_translation[:, [0, 2]]
    assert len(root) == 30
    assert np.ptp(root, axis=0).max() > 3.5  # the run crosses the room
    assert room.clearance(root).min() >= mocap_subject.MIN_PELVIS_CLEARANCE
    assert "leaves some camera's view" in capsys.readouterr().err
