"""``hmocap render overlay``: the skeleton projected onto every camera, gestures over depth.

Bags are cut from the shipped demo bags in ``tmp_path``: a few frame sets with their rig and
images, and an "outputs" bag whose skeleton is the ground truth with the head moved 20 cm, so
the picture must show the true joints green and the head red, where the camera model puts them.
"""
from __future__ import annotations

import numpy as np
import pytest

from hmocap_ros.cli import main as hmocap
from hmocap_ros.demo import DEMO_BAG, GESTURE_BAG
from hmocap_ros.io import topics
from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.io.bag_writer import LATCHED, BagWriter
from hmocap_ros.io.msg_factory import stamp_to_ns
from hmocap_ros.io.rig_messages import rig_from_msg

FRAMES = 4
HEAD_SHIFT_M = 0.2


def _cut(tmp_path, with_rig=True, with_images=True):
    """(images bag, outputs bag, stamps, truth joints (F, J, 3), joint names, rig)."""
    with BagReader(DEMO_BAG) as reader:
        rig_msg = reader.first(topics.CAMERA_RIG)
        truth = [m.msg for m in reader.messages([topics.GT_SKELETON])][10:10 + FRAMES]
        stamps = [stamp_to_ns(m.header.stamp) for m in truth]
        rig = rig_from_msg(rig_msg)
        image_topics = [topics.camera_image(n) for n in rig.names]
        images = [m for m in reader.messages(image_topics) if stamp_to_ns(m.msg.header.stamp) in stamps]
    bag, outputs = tmp_path / "images.mcap", tmp_path / "outputs.mcap"
    with BagWriter(bag) as writer:
        if with_rig:
            writer.add_topic(topics.CAMERA_RIG, "hmocap_interfaces/msg/CameraRig", LATCHED)
            writer.write(topics.CAMERA_RIG, rig_msg, stamps[0] - 1)
        for m in images if with_images else []:
            writer.write(m.topic, m.msg, stamp_to_ns(m.msg.header.stamp))
        for msg, stamp in zip(truth, stamps):
            writer.write(topics.GT_SKELETON, msg, stamp)
    names = list(truth[0].joint_names)
    head = names.index("head")
    with BagWriter(outputs) as writer:
        for msg, stamp in zip(truth, stamps):
            msg.body_id = "b0"
            msg.positions[head].y += HEAD_SHIFT_M
            writer.write("/skeleton", msg, stamp)
            msg.positions[head].y -= HEAD_SHIFT_M
    joints = np.array([[[p.x, p.y, p.z] for p in m.positions] for m in truth])
    return bag, outputs, stamps, joints, names, rig


def test_overlay_colours_each_joint_by_its_error_where_the_camera_sees_it(tmp_path):
    from hmocap_ros.viz.overlay import error_colours
    from hmocap_ros.viz.overlay_bag import multiview_pictures

    bag, outputs, stamps, joints, names, rig = _cut(tmp_path)
    width = 320
    pictures = list(multiview_pictures(bag, outputs, tile_width=width))
    assert [p.stamp_ns for p in pictures] == stamps
    picture = pictures[0].image
    tile_h = int(round(rig.cameras[0].height * width / rig.cameras[0].width))
    banner = picture.shape[0] - 2 * tile_h
    assert picture.shape[1] == 2 * width and banner > 0  # 4 cameras in a 2x2 grid under a banner
    assert (error_colours([0.0])[0] == [0, 255, 0]).all() and (error_colours([200.0])[0] == [255, 0, 0]).all()
    head, pelvis = names.index("head"), names.index("pelvis")
    for k, camera in enumerate(rig.cameras):
        row, col = divmod(k, 2)
        for joint, point, colour in ((pelvis, joints[0, pelvis], (0, 255, 0)),
                                     (head, joints[0, head] + [0, HEAD_SHIFT_M, 0], (255, 0, 0))):
            (u, v), depth = (x[0] for x in camera.project(point[None]))
            if not (depth > 0 and 2 <= u < camera.width - 2 and 2 <= v < camera.height - 2):
                continue
            x = int(round((u + 0.5) * width / camera.width - 0.5)) + col * width
            y = int(round((v + 0.5) * width / camera.width - 0.5)) + banner + row * tile_h
            patch = picture[y - 1:y + 2, x - 1:x + 2].reshape(-1, 3).astype(int)
            # the joint's dot, in its error's colour, where the camera model projects it
            assert np.abs(patch - colour).sum(axis=1).min() < 60, (camera.name, names[joint], patch)


def test_render_overlay_writes_a_video_and_png_frames(tmp_path, capsys):
    import cv2

    bag, outputs, stamps, _, _, _ = _cut(tmp_path)
    video = tmp_path / "overlay.mp4"
    assert hmocap(["render", "overlay", str(bag), "--outputs", str(outputs), "--out", str(video),
                   "--width", "160"]) == 0
    assert f"{FRAMES} pictures -> {video}" in capsys.readouterr().out
    capture = cv2.VideoCapture(str(video))
    frames = 0
    while capture.read()[0]:
        frames += 1
    assert frames == FRAMES
    folder = tmp_path / "frames"
    assert hmocap(["render", "overlay", str(bag), "--outputs", str(outputs), "--out", str(folder),
                   "--width", "160", "--frames", "2"]) == 0
    assert sorted(p.name for p in folder.iterdir()) == ["frame_00000.png", "frame_00001.png"]


def test_render_overlay_draws_gestures_on_depth(tmp_path):
    """The depth bag with its own ground truth given as the detections: a box per gesture."""
    from hmocap_ros.viz.overlay_bag import depth_pictures

    outputs = tmp_path / "gestures.mcap"
    with BagReader(GESTURE_BAG) as reader:
        truth = [m for m in reader.messages([topics.GT_GESTURES]) if len(m.msg.gestures)][:3]
    with BagWriter(outputs) as writer:
        for m in truth:
            writer.write("/gestures", m.msg, stamp_to_ns(m.msg.header.stamp))
    stamps = {stamp_to_ns(m.msg.header.stamp) for m in truth}
    pictures = {p.stamp_ns: p.image for p in depth_pictures(GESTURE_BAG, outputs, width=320, max_frames=200)}
    assert stamps <= set(pictures)
    for stamp in stamps:
        green = (pictures[stamp][:, :, 1] > 200) & (pictures[stamp][:, :, 0] < 80) & (pictures[stamp][:, :, 2] < 80)
        assert green.sum() > 20  # the detection's box and label


@pytest.mark.parametrize("case, expected", [
    ("no_rig", "no /camera_rig"),
    ("no_images", "no camera images (/cam_1/image_raw"),
    ("no_outputs", "no tracked skeletons (/skeleton"),
    ("depth_no_gestures", "no gesture detections (/gestures"),
    ("missing", "does not exist"),
    ("not_a_bag", "not a readable bag"),
])
def test_render_overlay_names_what_is_missing(tmp_path, capsys, case, expected):
    bag, outputs, *_ = _cut(tmp_path, with_rig=case != "no_rig", with_images=case != "no_images")
    args = [str(bag), "--outputs", str(outputs)]
    if case == "no_outputs":
        args = [str(bag)]
    elif case == "depth_no_gestures":
        args = [str(GESTURE_BAG)]
    elif case == "missing":
        args = [str(tmp_path / "nope.mcap")]
    elif case == "not_a_bag":
        junk = tmp_path / "junk.mcap"
        junk.write_bytes(b"not a bag at all" * 10)
        args = [str(junk)]
    assert hmocap(["render", "overlay", *args, "--out", str(tmp_path / "o.mp4")]) == 2
    err = capsys.readouterr().err
    assert expected in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err


def _video_stream(path) -> str:
    """ffmpeg's description of the file's video stream ("Video: h264 (High) ..., yuv420p, ...")."""
    import subprocess

    import imageio_ffmpeg

    probe = subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-hide_banner", "-i", str(path)],
                           capture_output=True, text=True)
    return next(line for line in probe.stderr.splitlines() if "Video:" in line)


def test_the_video_plays_in_browsers_with_tiles_at_the_recorded_size_and_a_legend(tmp_path):
    """H.264 in yuv420p with the index at the front (what browsers play inline), each camera's
    tile at its recorded size, and a legend row naming the colours."""
    from hmocap_ros.viz.overlay_bag import multiview_pictures, write_pictures

    bag, outputs, stamps, _, _, rig = _cut(tmp_path)
    pictures = list(multiview_pictures(bag, outputs))
    width, height = rig.cameras[0].width, rig.cameras[0].height
    picture = pictures[0].image
    assert picture.shape[1] == 2 * width and picture.shape[0] > 2 * height
    banner = picture[:picture.shape[0] - 2 * height]
    for colour in ((255, 255, 255), (255, 77, 0)):  # the truth's and the tracked body's swatches
        assert (np.abs(banner.astype(int) - colour).sum(axis=2) == 0).sum() >= 36, colour
    count, video = write_pictures(iter(pictures), tmp_path / "overlay.mp4")
    assert count == FRAMES
    stream = _video_stream(video)
    assert "h264" in stream and "yuv420p" in stream and f"{picture.shape[1]}x" in stream, stream
    data = video.read_bytes()
    assert data.index(b"moov") < data.index(b"mdat")  # +faststart: playable before fully loaded
    assert not list(tmp_path.glob(".*partial*"))
    _, webm = write_pictures(iter(pictures), tmp_path / "overlay.webm")
    assert "vp9" in _video_stream(webm)


def test_every_picture_of_a_video_has_one_size_with_and_without_a_body(tmp_path):
    """Frame sets before the person is tracked have the legend of the others: one picture size
    for the whole video, which ffmpeg needs."""
    from hmocap_ros.viz.overlay_bag import multiview_pictures, write_pictures

    bag, outputs, stamps, _, _, _ = _cut(tmp_path)
    later = tmp_path / "later.mcap"  # neither a skeleton nor the truth in the first frame set
    with BagReader(outputs) as skeletons, BagReader(bag) as truth, BagWriter(later) as writer:
        for m in [*list(skeletons.messages(["/skeleton"]))[1:], *list(truth.messages([topics.GT_SKELETON]))[1:]]:
            writer.write(m.topic, m.msg, m.log_time_ns)
    pictures = list(multiview_pictures(bag, later, truth=later))
    assert len({p.image.shape for p in pictures}) == 1
    count, video = write_pictures(iter(pictures), tmp_path / "v.mp4")
    import cv2

    capture = cv2.VideoCapture(str(video))
    frames = 0
    while capture.read()[0]:
        frames += 1
    assert count == frames == FRAMES


def test_each_body_id_has_its_colour_in_the_legend_and_over_the_cameras(tmp_path):
    """Two bodies, b0 only from the second frame set on: each keeps the colour of its id's place
    (b0 the first of BODY_COLOURS, b1 the second) in the legend and over the cameras, where its id
    is written above its head, also in a frame set where b1 is the only body."""
    from hmocap_ros.viz.overlay import BODY_COLOURS
    from hmocap_ros.viz.overlay_bag import multiview_keys, multiview_pictures

    bag, outputs, stamps, _, _, rig = _cut(tmp_path)
    two = tmp_path / "two.mcap"
    with BagReader(outputs) as reader, BagWriter(two) as writer:
        for m in reader.messages(["/skeleton"]):
            other = m.msg
            other.body_id = "b1"
            for p in other.positions:
                p.x += 1.0
            writer.write("/skeleton", other, m.log_time_ns)
        for m in list(reader.messages(["/skeleton"]))[1:]:
            writer.write("/skeleton", m.msg, m.log_time_ns)
    assert multiview_keys(["b0", "b1"], truth=False, extremities=True) == [
        (BODY_COLOURS[0], "b0 tracked"), (BODY_COLOURS[1], "b1 tracked"), ((255, 0, 255), "x detected body parts")]
    first, second = (p.image for p in multiview_pictures(bag, two, truth=two, max_frames=2))
    rows = first.shape[0] - 2 * rig.cameras[0].height
    for picture, shown in ((first, [False, True]), (second, [True, True])):
        banner, grid = picture[:rows], picture[rows:]
        for colour, here in zip(BODY_COLOURS[:2], shown):
            # its legend swatch always; its bones and id over the cameras where it is tracked
            assert (np.abs(banner.astype(int) - colour).sum(axis=2) == 0).sum() >= 36, colour
            assert ((np.abs(grid.astype(int) - colour).sum(axis=2) < 30).sum() >= 20) == here, colour


def test_each_body_is_scored_against_the_person_nearest_it():
    """With several people's truth, a body's joint errors are against the person whose truth
    lies nearest it, not against the subject's."""
    from types import SimpleNamespace

    from hmocap_ros.viz.overlay_bag import _body

    def skeleton(x, body_id=""):
        points = [SimpleNamespace(x=x + dx, y=1.0, z=0.0) for dx in (0.0, 0.1, 0.2)]
        return SimpleNamespace(body_id=body_id, joint_names=["pelvis", "l_hip", "r_hip"],
                               positions=points, parents=[-1, 0, 0])

    subject, other = skeleton(0.0), skeleton(2.0)
    near_other = _body(skeleton(2.01, "b1"), [subject, other])
    assert np.allclose(near_other.errors_mm, 10.0)
    near_subject = _body(skeleton(0.02, "b0"), [subject, other])
    assert np.allclose(near_subject.errors_mm, 20.0)
    assert _body(skeleton(1.0, "b2"), []).errors_mm is None
