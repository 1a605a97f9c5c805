"""``hmocap demo``: the shipped recordings through the real nodes over DDS, recorded and scored.

1. Body: the shipped 4-camera bag's images (``data/demo/room_4cam_jpeg.mcap``: 320x240 JPEG
   on image_transport's ``compressed`` topics, 12.5 fps, 0.8 s of the empty room, then 5.2 s of
   a person waving and directing traffic) are replayed into
   ``foreground_segmentation`` -> ``extremity_detection`` -> ``body_tracker``, the first two and
   ``camera_rig_publisher`` taking the compressed images (``image_transport:=compressed``),
   with ``camera_rig_publisher`` serving the bag's rig (``data/demo/room_4cam_jpeg_rig.yaml``)
   as in a room: ``camera_rig``, each image's ``camera_info`` and ``/tf_static`` (``world`` ->
   ``room`` -> cameras). Recorded to ``<out>/body.mcap`` (:func:`body_topics`): the
   images as the bag holds them and their camera_info, the rig,
   ``/tf_static``, the foregrounds, extremities, skeletons and markers, ``humans/bodies/tracked``,
   the body's joint states and shape, frames (``/tf``), shape and diagnostics, each output
   logged with the images of its stamp (``hmocap record --log-time input``), so the bag opens in
   Foxglove (``config/hmocap_foxglove.json``) or RViz (``config/hmocap.rviz``) with each skeleton
   over its own images (the demo checks it: :func:`log_time_gap`). ``<out>/body_overlay.mp4``
   (H.264, each camera's tile at its recorded size, a legend) shows the skeleton over the
   cameras, coloured by its error against the bag's ground truth (``hmocap render overlay``).
2. Gestures: the shipped depth bag (``data/demo/gestures_depth.mcap``) is replayed into
   ``gesture_detection``; the depth images, camera_info, gestures and probability images are
   recorded to ``<out>/gestures.mcap``, and drawn in ``<out>/gestures_overlay.mp4``.

Every node is its own process over DDS on loopback, with the one-host Fast DDS profile
(``config/fastdds_local.xml``, :func:`hmocap_ros.processes.loopback_dds_env`); each stage's logs
go to ``<out>/logs/body/`` and ``<out>/logs/gestures/``. The replay starts once its publishers
have matched every subscription of the nodes and the recorder, which subscribe reliably: no
frame is lost to discovery finishing late on a loaded machine. The background model learns
only where the landmark network sees nobody, so it cannot learn the person either. The demo
then compares what came out with the bags' ground truth: foreground F1, 3D joint error (mm) and
the tracker's time per frame; gestures found with the right class within 10 pixels (at 640x480,
scaled). The body stage passes with a mask for every image, a pose for every frame with the
person, a foreground F1 of at least :data:`MIN_FOREGROUND_F1` and a mean joint error of at most
:data:`MAX_JOINT_ERROR_MM` (:class:`BodyScores`).
Each node queues every frame (``queue_depth``) and works through them in stamp order
(``latest_only:=false``), the tracker at its full particle budget; the demo waits for a pose per
frame with a person. The body bag is replayed at a quarter of real time, so the keypoints,
the slowest stage, stay within the tracker's hold (:data:`hmocap_ros.frame_intake.HOLD_NS`) of
the masks even on a loaded machine.

The run is written beside ``<out>`` and takes its place once complete: a run stopped with
Ctrl-C leaves the previous results whole.
"""

from __future__ import annotations

import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hmocap_ros.eval.metrics import match_joints, mpjpe
from hmocap_ros.io import topics
from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.io.conversions import image_to_numpy
from hmocap_ros.io.image_codec import transport_topic
from hmocap_ros.io.msg_factory import stamp_to_ns
from hmocap_ros.processes import DDS_PROFILE_VARIABLES, loopback_dds_env, replay_through_nodes
from hmocap_ros.segmentation import mask_scores

DATA_DIR = Path(__file__).resolve().parent / "data" / "demo"
#: The body demo's recording: 4 cameras at 320x240, JPEG (image_transport's ``compressed``),
#: 12.5 fps, 0.8 s of the empty room then 5.2 s of a person moving (``data/demo/SOURCES.md``).
BODY_BAG = DATA_DIR / "room_4cam_jpeg.mcap"
BODY_RIG = DATA_DIR / "room_4cam_jpeg_rig.yaml"
#: A short raw recording (4 cameras at 160x120, 28 frame sets: 8 of the empty room, then 20 of
#: a person waving) for quick checks of the nodes and the offline commands.
DEMO_BAG = DATA_DIR / "mocap_4cam.mcap"
DEMO_RIG = DATA_DIR / "mocap_4cam_rig.yaml"
GESTURE_BAG = DATA_DIR / "gestures_depth.mcap"
_IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")

#: Image subscriptions of the demo's nodes: reliable, so that the replay, which starts once its
#: publishers have matched every node's subscription (``--wait-subscribers``), loses no frame to
#: the subscriber's side of discovery finishing later (the replay's reliable publishers hold
#: what was sent and send it again).
RELIABLE_IMAGES = ["-p", "image_reliability:=reliable"]
#: Frames each node of the demo queues: the whole recording, so a node behind the replay drops none.
QUEUE_ARGS = ["-p", "queue_depth:=200"]
#: body_tracker settings of the demo: every frame is queued and tracked (a live room,
#: ``latest_only`` as the node's default, would rather skip frames than lag).
TRACKER_ARGS = [*QUEUE_ARGS, "-p", "latest_only:=false", *RELIABLE_IMAGES]
#: extremity_detection: its default detector, every frame set in stamp order.
EXTREMITY_ARGS = [*QUEUE_ARGS, "-p", "latest_only:=false", *RELIABLE_IMAGES]
#: foreground_segmentation settings of the demo: every frame in stamp order, the background
#: learnt where the landmark network sees no person (``learn_from:=person_masks``), so even a
#: replay whose first frames were lost could not learn the person into the background; blob and
#: hole sizes for its 320x240 images.
FOREGROUND_ARGS = [*QUEUE_ARGS, "-p", "learn_from:=person_masks", "-p", "learn_frames:=8", "-p", "latest_only:=false",
                   "-p", "min_blob_area:=80", "-p", "max_hole_area:=240", *RELIABLE_IMAGES]
#: Largest mean 3D joint error (mm) of a passing body demo, well above what its recording scores
#: (README.md, the ``make demo`` paragraph), so a loaded machine passes and a lost body fails.
MAX_JOINT_ERROR_MM = 100.0
#: Smallest foreground F1 (masks against the true silhouettes, frames with the person) of a
#: passing body demo, below what its recording scores (README.md) and far above an empty mask's.
MIN_FOREGROUND_F1 = 0.8


def _cameras(bag: Path) -> list[str]:
    return camera_images(bag)[0]


def camera_images(bag: Path) -> tuple[list[str], str]:
    """The cameras of ``bag`` and the transport of their images: ``raw`` (sensor_msgs/Image on
    ``/<camera>/image_raw``) or ``compressed`` (sensor_msgs/CompressedImage on
    ``/<camera>/image_raw/compressed``)."""
    with BagReader(bag) as reader:
        images = {t: info.msgtype for t, info in reader.topics(compressed_as_raw=True).items()
                  if t.endswith("/image_raw") and info.msgtype in _IMAGE_TYPES}
    cameras = sorted(t.strip("/").split("/")[0] for t in images)
    compressed = any(msgtype == "sensor_msgs/msg/CompressedImage" for msgtype in images.values())
    return cameras, "compressed" if compressed else "raw"


def _by_stamp(bag: Path, topic_list: list[str]) -> dict[str, dict[int, Any]]:
    """The messages of each topic by their header stamp."""
    out: dict[str, dict[int, Any]] = {t: {} for t in topic_list}
    with BagReader(bag) as reader:
        present = [t for t in topic_list if t in reader.topics()]
        for m in reader.messages(present):
            out[m.topic][stamp_to_ns(m.msg.header.stamp)] = m.msg
    return out


def _joints(msg) -> tuple[list[str], np.ndarray]:
    return list(msg.joint_names), np.array([[p.x, p.y, p.z] for p in msg.positions])


def body_topics(cameras: list[str], transport: str = "raw") -> list[str]:
    """What the body demo records: the inputs (camera images in ``transport``, as the bag holds
    them) and the rig as a room has them, and every output of the nodes (what the viewers'
    layouts show, ``config/hmocap.rviz`` and ``config/hmocap_foxglove.json``)."""
    return [*(transport_topic(topics.camera_image(c), transport) for c in cameras),
            *(f"/{c}/camera_info" for c in cameras),
            topics.CAMERA_RIG, "/tf_static", *(topics.camera_foreground(c) for c in cameras), "/extremities",
            "/extremities/points", "/skeleton", "/skeleton_markers", "/humans/bodies/tracked",
            "/humans/bodies/b0/joint_states", "/humans/bodies/b0/body_shape", "/tf", "/body_shape", "/diagnostics"]


def body_nodes(cameras: list[str], transport: str, rig: Path) -> list[tuple[str, str, list[str], str]]:
    """The body demo's nodes for :func:`~hmocap_ros.processes.replay_through_nodes`, taking the
    camera images in ``transport``."""
    images = ["-p", f"image_transport:={transport}"]
    return [("camera_rig_publisher", "hmocap_ros.nodes.camera_rig_publisher",
             ["--ros-args", "-p", f"rig_file:={rig}", *images], "serving rig"),
            ("foreground_segmentation", "hmocap_ros.nodes.foreground_segmentation",
             ["--ros-args", "-p", f"cameras:=[{','.join(cameras)}]", *FOREGROUND_ARGS, *images], "segmenting"),
            # its masks in the transport of its images (the foreground node encodes them when subscribed)
            ("extremity_detection", "hmocap_ros.nodes.extremity_detection",
             ["--ros-args", *EXTREMITY_ARGS, *images], "waiting for the rig"),
            ("body_tracker", "hmocap_ros.nodes.body_tracker", ["--ros-args", *TRACKER_ARGS], "waiting for the rig")]


@dataclass(frozen=True)
class BodyScores:
    """What the body demo measured against the bag's ground truth."""

    masks: int  #: foreground masks of the first camera
    images: int  #: frame sets replayed
    foreground_f1: float  #: mean F1 of the masks of frames with the person (NaN: none)
    poses: int  #: frames with a tracked pose that the truth has a skeleton for
    person_frames: int  #: frames with the person (a true skeleton)
    joint_errors_mm: list[float]  #: mean 3D joint error of each of those poses

    @property
    def mean_error_mm(self) -> float:
        return float(np.mean(self.joint_errors_mm)) if self.joint_errors_mm else float("nan")

    def passed(self) -> bool:
        """Every frame segmented, a pose for every frame with the person, the masks and the
        poses within :data:`MIN_FOREGROUND_F1` and :data:`MAX_JOINT_ERROR_MM`."""
        return (self.masks == self.images and self.poses == self.person_frames
                and self.foreground_f1 >= MIN_FOREGROUND_F1 and self.mean_error_mm <= MAX_JOINT_ERROR_MM)


def run_body_demo(out: Path, env: dict, rate: float = 0.25, bag: Path = BODY_BAG, rig: Path = BODY_RIG) -> bool:
    cameras, transport = camera_images(bag)
    with BagReader(bag) as reader:
        n_person = reader.topics()[topics.GT_SKELETON].count
    out_bag = out / "body.mcap"
    fg_topics = [topics.camera_foreground(c) for c in cameras]
    image_topics = [transport_topic(topics.camera_image(c), transport) for c in cameras]
    print(f"body: {bag.name}, {len(cameras)} cameras ({transport} images) -> foreground_segmentation -> "
          f"extremity_detection -> body_tracker (replay at {rate:g}x real time)")
    t0 = time.monotonic()
    replay_through_nodes(
        bag, body_nodes(cameras, transport, rig), body_topics(cameras, transport), out_bag, env,
        out / "logs" / "body",
        replay_topics=image_topics,
        # camera_rig_publisher, foreground_segmentation, extremity_detection and the recorder take
        # every image
        replay_rate=rate, settle=3.0, expect={"/skeleton": n_person}, subscribers=4)
    elapsed = time.monotonic() - t0

    truth = _by_stamp(bag, [topics.GT_SKELETON, *(topics.gt_silhouette(c) for c in cameras)])
    got = _by_stamp(out_bag, ["/skeleton", "/diagnostics", "/extremities", *fg_topics])
    f1 = []
    for cam, fg_topic in zip(cameras, fg_topics, strict=True):
        silhouettes = truth[topics.gt_silhouette(cam)]
        pairs = [(image_to_numpy(m) > 0, image_to_numpy(silhouettes[s]) > 0) for s, m in got[fg_topic].items()
                 if s in silhouettes and (image_to_numpy(silhouettes[s]) > 0).sum() > 0]
        if pairs:
            f1.append(float(np.mean(mask_scores(*map(np.stack, zip(*pairs, strict=True))).f1)))
    n_images = len(truth[topics.gt_silhouette(cameras[0])])
    print(f"  foreground: {len(got[fg_topics[0]])}/{n_images} masks per camera, "
          f"F1 vs ground truth {np.mean(f1) if f1 else float('nan'):.2f} (frames with the person)")

    extremities = got["/extremities"].values()
    labelled = sum(len([lab for lab in m.labels if lab != "unknown"]) for m in extremities)
    detector = next(iter(extremities)).detector if extremities else "none"
    print(f"  extremity_detection ({detector}): {len(extremities)}/{n_images} frame sets, "
          f"{labelled / max(len(extremities), 1):.1f} labelled detections per set")
    errors = []
    seconds_in: list[int] = []  # whole seconds since the person's first frame
    first = min(truth[topics.GT_SKELETON], default=0)
    for stamp, msg in sorted(got["/skeleton"].items()):
        if stamp in truth[topics.GT_SKELETON]:
            names, est = _joints(msg)
            gt_names, gt = _joints(truth[topics.GT_SKELETON][stamp])
            i, j = match_joints(names, gt_names)
            errors.append(float(mpjpe(est[i], gt[j])))  # mm
            seconds_in.append(int((stamp - first) // 1_000_000_000))
    seconds = [float(kv.value) for d in got["/diagnostics"].values() for s in d.status
               if s.name.startswith("body_tracker") and s.message != "searching"
               for kv in s.values if kv.key == "seconds_per_frame"]
    scores = BodyScores(len(got[fg_topics[0]]), n_images, float(np.mean(f1)) if f1 else float("nan"),
                        len(errors), len(truth[topics.GT_SKELETON]), errors)
    per_second = [f"{np.mean([e for e, t in zip(errors, seconds_in, strict=True) if t == k]):.0f}"
                  for k in sorted(set(seconds_in))]
    print(f"  body_tracker: {scores.poses}/{scores.person_frames} frames with a pose, mean joint error "
          f"{scores.mean_error_mm:.0f} mm (per second of motion: {' '.join(per_second) or '-'}; largest "
          f"{max(errors) if errors else float('nan'):.0f}), "
          f"{np.median(seconds) if seconds else float('nan'):.2f} s per frame")
    print(f"  recorded {out_bag} in {elapsed:.0f} s")
    if not scores.passed():
        print(f"  body: FAILED: wants every frame segmented and tracked, foreground F1 >= {MIN_FOREGROUND_F1:g} "
              f"and mean joint error <= {MAX_JOINT_ERROR_MM:.0f} mm")
    return scores.passed()


def render(bag: Path, out: Path, truth: Path) -> Path | None:
    """``hmocap render overlay BAG --truth TRUTH --out OUT``; the video, or None (said why)."""
    from hmocap_ros.viz.overlay_bag import OverlayError, render_overlay

    try:
        count, path = render_overlay(bag, out, truth=truth)
    except (OverlayError, OSError) as err:
        print(f"  no overlay: {err}")
        return None
    print(f"  overlay: {count} pictures -> {path}")
    return path


def run_gesture_demo(out: Path, env: dict, rate: float = 1.0) -> bool:
    """Replay the shipped depth bag into ``gesture_detection`` over DDS, record ``/gestures`` and
    print the detections against the bag's ground truth (class right and within 10 px at 640x480,
    scaled by the image width, as ``hmocap eval gestures``); True when every frame was answered."""
    out_bag = out / "gestures.mcap"
    print(f"gestures: {GESTURE_BAG.name} -> gesture_detection (replay at {rate:g}x real time)")
    t0 = time.monotonic()
    procs = replay_through_nodes(
        GESTURE_BAG,
        [("gesture_detection", "hmocap_ros.nodes.gesture_detection",
          ["--ros-args", "-p", "latest_only:=false", *RELIABLE_IMAGES], "detecting gestures")],
        ["/gestures", "/gestures/probability", topics.DEPTH_IMAGE, topics.DEPTH_INFO], out_bag, env,
        out / "logs" / "gestures",
        replay_topics=[topics.DEPTH_IMAGE, topics.DEPTH_INFO], replay_rate=rate, settle=2.0,
        subscribers=2)  # gesture_detection and the recorder
    elapsed = time.monotonic() - t0
    for line in procs["gesture_detection"].output().splitlines():  # what the node loaded and saw
        if "gesture forest" in line or "depth camera" in line:
            print("  node: " + line.split("]: ", 1)[-1])
    truth = _by_stamp(GESTURE_BAG, [topics.GT_GESTURES])[topics.GT_GESTURES]
    got = _by_stamp(out_bag, ["/gestures"])["/gestures"]
    with BagReader(GESTURE_BAG) as reader:
        info = reader.first(topics.DEPTH_INFO)
    width = info.width if info is not None else 640
    radius = 10.0 * width / 640.0
    hits: dict[str, int] = {}
    labelled: dict[str, int] = {}
    false = hidden = 0
    lines = []
    for stamp in sorted(truth):
        gt = list(truth[stamp].gestures)
        det = list(got[stamp].gestures) if stamp in got else []
        right = [any(d.class_id == g.class_id and np.hypot(d.u - g.u, d.v - g.v) <= radius for g in gt) for d in det]
        if gt and not gt[0].position_valid:  # the reference point is hidden: not scored
            hidden += 1
        else:
            for g in gt:
                labelled[g.name] = labelled.get(g.name, 0) + 1
                hits[g.name] = hits.get(g.name, 0) + any(r and d.class_id == g.class_id for r, d in zip(right, det))
            false += sum(not r for r in right)
        if det or gt:
            found = ", ".join(f"{d.name} {d.score:.2f} at ({d.u:.0f}, {d.v:.0f})"
                              + (f" {d.position.z:.2f} m" if d.position_valid else "")
                              + ("" if r else " (false)") for d, r in zip(det, right))
            truth_text = ", ".join(f"{g.name} at ({g.u:.0f}, {g.v:.0f})" for g in gt) or "-"
            lines.append(f"    {(stamp - min(truth)) * 1e-9:5.1f} s  truth: {truth_text:24s} found: {found or '-'}")
    print(f"  {len(got)}/{len(truth)} frames answered in {elapsed:.0f} s; found {sum(hits.values())} of "
          f"{sum(labelled.values())} held gestures, {false} false detections (class right and within "
          f"{radius:.0f} px at {width} px wide; {hidden} frames with a hidden reference point not scored)")
    print("  per gesture: " + ", ".join(f"{n} {hits[n]}/{labelled[n]}" for n in labelled))
    for line in lines[:: max(1, len(lines) // 12)]:
        print(line)
    print(f"  recorded {out_bag}")
    return len(got) == len(truth)


def run_demo(out: str | Path = "out/demo", domain_id: int | None = None) -> int:
    """Run both demos; 0 when every node answered every frame.

    The run writes into ``.<out name>.partial`` beside ``out`` and takes the place of ``out``
    only once it is complete: a run stopped half-way (Ctrl-C) leaves the previous results whole."""
    out = Path(out)
    work = out.parent / f".{out.name}.partial"
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    env = loopback_dds_env(domain_id=domain_id)
    print(f"demo: DDS domain {env.get('ROS_DOMAIN_ID', '0')}, discovery {env['ROS_AUTOMATIC_DISCOVERY_RANGE']}, "
          f"profile {env.get(DDS_PROFILE_VARIABLES[0], 'none')}; outputs and logs in {out} "
          f"(written to {work} until the run ends)")
    ok_body = run_body_demo(work, env)
    gap = log_time_gap(work / "body.mcap", "/skeleton")
    print(f"  viewers: every skeleton logged within {gap:.3f} s of its images' log time" if gap is not None
          else "  viewers: no skeleton with its images in the bag")
    body_video = render(work / "body.mcap", work / "body_overlay.mp4", BODY_BAG)
    ok_gestures = run_gesture_demo(work, env)
    gesture_video = render(work / "gestures.mcap", work / "gestures_overlay.mp4", GESTURE_BAG)
    _replace(out, work)
    ok = (ok_body and ok_gestures and body_video is not None and gesture_video is not None
          and gap is not None and gap <= MAX_LOG_TIME_GAP_S)
    print(f"demo: {'OK' if ok else 'FAILED'}.")
    print(f"  videos: {out / body_video.name if body_video else '-'}  "
          f"{out / gesture_video.name if gesture_video else '-'}")
    print(f"  bags:   {out / 'body.mcap'}  {out / 'gestures.mcap'}")
    print(f"  logs:   {out / 'logs' / 'body'}  {out / 'logs' / 'gestures'}")
    print(f"  look at the body bag in Foxglove with the layout {_config('hmocap_foxglove.json')}, or in RViz "
          f"with {_config('hmocap.rviz')} (docs/viewing.md); live: hmocap view")
    return 0 if ok else 1


#: Largest log-time difference (s) between a skeleton and the images of its stamp in the demo's
#: bag: a viewer playing it draws each skeleton over its own images.
MAX_LOG_TIME_GAP_S = 0.1


def log_time_gap(bag: Path, output_topic: str) -> float | None:
    """The largest difference (s) between the log time of a message of ``output_topic`` and
    that of the camera images (raw or compressed) with its header stamp; None when no output
    has images."""
    with BagReader(bag) as reader:
        available = reader.topics(compressed_as_raw=True)
        image_topics = [t for t, info in available.items() if t.endswith("/image_raw") and info.msgtype in _IMAGE_TYPES]
        if output_topic not in available or not image_topics:
            return None
        images: dict[int, list[int]] = {}
        outputs: list[tuple[int, int]] = []
        for m in reader.messages([*image_topics, output_topic]):
            stamp = stamp_to_ns(m.msg.header.stamp)
            if m.topic == output_topic:
                outputs.append((stamp, m.log_time_ns))
            else:
                images.setdefault(stamp, []).append(m.log_time_ns)
    gaps = [abs(log_ns - image_ns) for stamp, log_ns in outputs for image_ns in images.get(stamp, [])]
    return max(gaps) * 1e-9 if gaps else None


def _replace(out: Path, work: Path) -> None:
    """Put the finished run ``work`` in the place of ``out`` (the previous run, removed only now)."""
    old = out.parent / f".{out.name}.previous"
    if old.exists():
        shutil.rmtree(old)
    if out.exists():
        out.rename(old)
    work.rename(out)
    if old.exists():
        shutil.rmtree(old)


def _config(name: str) -> str:
    from hmocap_ros.config_files import find_config_file

    path = find_config_file(name)
    return str(path) if path is not None else f"config/{name}"
