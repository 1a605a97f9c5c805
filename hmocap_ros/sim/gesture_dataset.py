"""``hmocap sim gestures``: a depth bag of people gesturing among clutter, with ground truth.

Renders takes of simulated subjects (``gesture_set``) in furnished rooms (``depth_scene``)
with a Kinect-like depth camera and writes, per frame, with one shared ``header.stamp``
(frames ``1/fps`` apart from 1,700,000,000 s; a 1 s gap where the room changes):

==========================  ======================================  ==========================
topic                       type                                    content
==========================  ======================================  ==========================
``/depth/image_raw``        sensor_msgs/Image 16UC1                 millimetres, 0 = invalid
``/depth/camera_info``      sensor_msgs/CameraInfo                  fx = fy = 575 at 640x480
``/ground_truth/gestures``  hmocap_interfaces/GestureArray          zero or one Gesture
==========================  ======================================  ==========================

frame_id is ``depth_optical_frame`` everywhere.  A Gesture is present while a subject holds
one of the six gestures (``gesture_set.GESTURE_CLASSES``, class ids 1..6; score = volume = 1);
idle, walking, random or near-miss arm poses and the transitions between takes are
background (empty array).  ``u, v`` is the pixel of the gesture's reference point
(``gesture_set.REFERENCE_POINTS``: palm centre, finger on the lips, forearm crossing, hand
contact point), ``position`` the 3D point of the person's surface seen at that pixel (the
clean z-buffer depth, back-projected), in metres in the optical frame.  When the reference
point is hidden (by the person's own body, e.g. a hand turned away, or anything else) or
outside the image, the Gesture keeps its class and (u, v) but ``position_valid`` is false:
evaluators should neither reward nor penalise a detection in such frames.

Sequence: the frames are split evenly between ``--subjects`` subjects with identities
``--subject-offset`` .. ``+ subjects - 1`` (a subject's body and clothing depend on its id
only, so sets generated with disjoint id ranges never share a person; use them for train
and test).  Each subject performs takes in a random room (the room and the bystanders
change every few takes and with the seed; bystanders get identities >= 10^6, never a
subject's; ``--background close`` puts the back wall 0.15-0.85 m behind the person):
a short transition from the previous pose (1-3 frames, background), then
``--hold`` (default 5-10) frames holding a gesture with small motion, or as many frames of
a negative kind.  Takes follow shuffled blocks of the six gestures plus three negatives, so classes
are balanced and about half of the frames are background.  Same arguments, same bytes.

Side files next to the bag (``run.mcap`` -> ``run.labels.json``, ``run.contact.png``):

* labels JSON: ``{"format": "hmocap-gesture-labels/1", "seed", "classes": {id: name},
  "camera": {...}, "subjects": {id: {...}}, "layouts": {id: {...}}, "frames": [...]}``, one
  frame entry per depth image: ``index, stamp_ns, subject, layout, take, phase`` ("hold",
  "negative", "transition"), ``kind`` (gesture or negative kind), ``class_id`` (0 =
  background), ``name``, ``side``, ``u, v, position`` (null for background), ``visible``
  (= position_valid), ``distance_m`` (camera to pelvis);
* contact sheet PNG: a few frames per class, depth colour-mapped (0.5-4.5 m), with the GT
  point and class name drawn.
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from hmocap_ros.body import load_body_model
from hmocap_ros.io import topics
from hmocap_ros.io.bag_writer import whole_bag
from hmocap_ros.io.conversions import dict_to_camera_info, numpy_to_image
from hmocap_ros.io.msg_factory import RosbagsFactory, make_header
from hmocap_ros.sim import gesture_set as gs
from hmocap_ros.sim.depth_scene import BACKGROUNDS, Layout, make_layout, pixel_to_optical, render_depth

START_NS = 1_700_000_000_000_000_000
LABELS_FORMAT = "hmocap-gesture-labels/1"
TAKES_PER_LAYOUT = 8
NEGATIVES_PER_BLOCK = 3
HOLD_FRAMES = (5, 10)
TRANSITION_FRAMES = (1, 3)
MAX_YAW_DEG = 30.0
WALK_STEP_M = 0.11  # per frame at 10 fps: 1.1 m/s
SURFACE_TOLERANCE_M = 0.12  # the surface at (u, v) must be this close to the reference point
# Random streams: one per purpose, so e.g. the noise never shifts the poses.
_STREAM_POSES, _STREAM_NOISE, _STREAM_LAYOUT = 1, 2, 3


def sidecar_paths(bag: str | Path) -> tuple:
    """(labels JSON, contact sheet PNG) paths next to a bag."""
    bag = Path(bag)
    stem = bag.with_suffix("") if bag.suffix == ".mcap" else bag
    return stem.with_name(stem.name + ".labels.json"), stem.with_name(stem.name + ".contact.png")


@dataclass
class Actor:
    """A person in the scene: subject, current world pose and cached mesh."""

    subject: gs.Subject
    params: np.ndarray | None = None
    _cache: tuple = field(default=(None, None))

    def vertices(self, model) -> np.ndarray:
        if self._cache[0] is None or not np.array_equal(self._cache[0], self.params):
            verts = gs.posed_vertices(model, self.subject, self.params)
            self._cache = (self.params.copy(), verts)
        return self._cache[1]


@dataclass
class FrameState:
    params: np.ndarray
    phase: str
    kind: str
    side: str
    take: int


def _lerp_pose(model, a: np.ndarray, b: np.ndarray, t: float) -> np.ndarray:
    out = (1.0 - t) * a + t * b
    k = model.skeleton.dof_index("root_yaw")
    out[k] = a[k] + t * ((b[k] - a[k] + np.pi) % (2 * np.pi) - np.pi)
    return out


def _schedule(rng: np.random.Generator):
    """Endless take kinds: shuffled blocks of the six gestures plus negatives."""
    kinds = list(gs.NEGATIVE_WEIGHTS)
    w = np.array([gs.NEGATIVE_WEIGHTS[k] for k in kinds])
    while True:
        block = list(gs.GESTURE_CLASSES) + [str(k) for k in rng.choice(kinds, NEGATIVES_PER_BLOCK, p=w / w.sum())]
        yield from (block[i] for i in rng.permutation(len(block)))


def _in_zone(rng, zone, radius_scale=1.0):
    x0, z0, r = zone
    a, rad = rng.uniform(0, 2 * np.pi), r * radius_scale * np.sqrt(rng.random())
    return x0 + rad * np.cos(a), z0 + rad * np.sin(a)


def _facing_yaw(camera_pos, x, z):
    return float(np.arctan2(camera_pos[0] - x, camera_pos[2] - z))


def _take_frames(model, actor: Actor, kind: str, layout: Layout, rng, take: int,
                 hold=HOLD_FRAMES) -> list:
    """World poses of one take of ``actor``: a transition from its current pose (if any),
    then ``hold`` (min, max) frames of the gesture or negative."""
    cam = layout.camera.position
    n = int(rng.integers(hold[0], hold[1] + 1))
    subj = actor.subject
    frames = []
    if kind == "walk":
        heading = float(rng.choice([-1, 1]) * np.pi / 2 + rng.uniform(-0.6, 0.6))
        x, z = _in_zone(rng, layout.zone, 0.2)  # the path crosses the zone near its centre
        step = WALK_STEP_M * np.array([np.sin(heading), np.cos(heading)])
        x, z = np.array([x, z]) - step * n / 2
        spec = gs.negative_spec(model, subj, "walk", rng)
        standing = gs.solve_spec(model, subj, spec)
        phase0 = rng.uniform(0, 2 * np.pi)
        poses = []
        for i in range(n):
            p = gs.ground(model, subj, gs.walk_params(model, standing, phase0 + i * 2 * np.pi * WALK_STEP_M / 1.2))
            poses.append(gs.place(model, p, x + i * step[0], z + i * step[1], heading))
        side = ""
    else:
        x, z = _in_zone(rng, layout.zone)
        yaw = _facing_yaw(cam, x, z) + np.deg2rad(rng.uniform(-MAX_YAW_DEG, MAX_YAW_DEG))
        camera_body = gs.world_to_body(x, z, yaw, cam)
        spec = gs.pose_spec(model, subj, kind, rng, camera_body=camera_body)
        # only the gestures need their targets met exactly (restarts cost time)
        a = gs.solve_spec(model, subj, gs.jitter_spec(spec, rng, model=model),
                          restarts=None if kind in gs.GESTURE_CLASSES else 0)
        b = gs.solve_spec(model, subj, gs.jitter_spec(spec, rng, model=model), start=a, iterations=15,
                          restarts=0)
        sway = rng.normal(0.0, 0.01, (2, 3))
        poses = []
        for i in range(n):
            t = i / max(n - 1, 1)
            dx, dz, dyaw = (1 - t) * sway[0] + t * sway[1]
            poses.append(gs.place(model, _lerp_pose(model, a, b, t), x + dx, z + dz, yaw + dyaw))
        side = spec.side if (kind in gs.GESTURE_CLASSES or spec.stages) else ""
    if actor.params is not None:
        m = int(rng.integers(TRANSITION_FRAMES[0], TRANSITION_FRAMES[1] + 1))
        for i in range(m):
            frames.append(FrameState(_lerp_pose(model, actor.params, poses[0], (i + 1) / (m + 1)),
                                     "transition", kind, side, take))
    phase = "hold" if kind in gs.GESTURE_CLASSES else "negative"
    frames += [FrameState(p, phase, kind, side, take) for p in poses]
    return frames


def _bystander_pose(model, actor: Actor, spot, layout: Layout, rng) -> np.ndarray:
    x, z, yaw = spot
    kind = str(rng.choice([k for k in gs.NEGATIVE_KINDS if k != "walk"]))
    cam = gs.world_to_body(x, z, yaw, layout.camera.position)
    p = gs.solve_spec(model, actor.subject, gs.negative_spec(model, actor.subject, kind, rng, camera_body=cam),
                      iterations=20, restarts=0)
    return gs.place(model, p, x, z, yaw + rng.uniform(-0.3, 0.3))


@dataclass
class GroundTruth:
    class_id: int = 0
    name: str = "background"
    u: float | None = None
    v: float | None = None
    position: list | None = None
    visible: bool = False


def ground_truth(model, actor: Actor, state: FrameState, layout: Layout, render,
                 face_range: tuple) -> GroundTruth:
    """Label of one frame: class, reference pixel, surface point and visibility."""
    if state.phase != "hold":
        return GroundTruth()
    cam = layout.camera
    kin = gs.kinematics(model, actor.subject, state.params)
    ref = gs.reference_point(model, kin, state.kind, state.side)[0]
    pix, depth = cam.project(ref)
    u, v = float(pix[0]), float(pix[1])
    gt = GroundTruth(gs.class_id(state.kind), state.kind, u, v)
    col, row = int(round(u)), int(round(v))
    if not (cam.in_image(pix) and depth > 0 and 0 <= col < cam.width and 0 <= row < cam.height):
        gt.position = pixel_to_optical(cam, u, v, float(depth)).tolist()
        return gt
    z = float(render.zbuf[row, col])
    fid = int(render.face_id[row, col])
    parts = set(gs.reference_parts(model, state.kind, state.side))
    on_person = face_range[0] <= fid < face_range[1]
    if on_person:
        tri = model.faces[fid - face_range[0]]
        on_person = bool(parts.intersection(model.vertex_part[tri].tolist()))
    gt.visible = bool(on_person and np.isfinite(z) and abs(z - depth) < SURFACE_TOLERANCE_M)
    gt.position = pixel_to_optical(cam, u, v, z if gt.visible else float(depth)).tolist()
    return gt


def gesture_array(factory, stamp_ns: int, frame_id: str, gt: GroundTruth):
    """The /ground_truth/gestures message of one frame."""
    gestures = []
    if gt.class_id:
        x, y, z = gt.position
        gestures.append(factory.make(
            "hmocap_interfaces/msg/Gesture", name=gt.name, class_id=gt.class_id, score=1.0, volume=1.0,
            u=gt.u, v=gt.v, position=factory.make("geometry_msgs/msg/Point", x=x, y=y, z=z),
            position_valid=gt.visible))
    return factory.make("hmocap_interfaces/msg/GestureArray",
                        header=make_header(factory, stamp_ns, frame_id), gestures=gestures)


# ---------------------------------------------------------------------------------------
# Contact sheet
# ---------------------------------------------------------------------------------------

TILE = (320, 240)


def colour_depth(depth_mm: np.ndarray, near_m: float = 0.5, far_m: float = 4.5) -> np.ndarray:
    """BGR image of a depth map: turbo colour map from near (red) to far (blue), black = 0."""
    d = depth_mm.astype(np.float32) / 1000.0
    t = np.clip((far_m - d) / (far_m - near_m), 0, 1)
    img = cv2.applyColorMap((t * 255).astype(np.uint8), cv2.COLORMAP_TURBO)
    img[depth_mm == 0] = 0
    return img


def contact_tile(depth_mm: np.ndarray, gt: GroundTruth, caption: str) -> np.ndarray:
    """One annotated tile of the contact sheet."""
    h, w = depth_mm.shape
    img = cv2.resize(colour_depth(depth_mm), TILE, interpolation=cv2.INTER_NEAREST)
    sx, sy = TILE[0] / w, TILE[1] / h
    if gt.class_id:
        c = (int(round((gt.u + 0.5) * sx - 0.5)), int(round((gt.v + 0.5) * sy - 0.5)))
        colour = (255, 255, 255) if gt.visible else (128, 128, 128)
        cv2.circle(img, c, 9, (0, 0, 0), 3)
        cv2.circle(img, c, 9, colour, 2)
        cv2.drawMarker(img, c, colour, cv2.MARKER_CROSS, 8, 1)
    cv2.rectangle(img, (0, 0), (TILE[0], 18), (0, 0, 0), -1)
    cv2.putText(img, caption, (4, 13), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (255, 255, 255), 1, cv2.LINE_AA)
    return img


def select_sheet_frames(records: list, per_class: int) -> dict:
    """Frame indices for the contact sheet: per class (0 = background, from the negative
    takes) up to ``per_class`` frames with a visible reference point, from takes spread
    over the bag (the middle frame of each), then more frames of the same takes."""
    groups: dict = {}
    for r in records:
        if (r["visible"] if r["class_id"] else r["phase"] == "negative"):
            groups.setdefault(r["class_id"], {}).setdefault(r["take"], []).append(r["index"])
    chosen = {}
    for cid, takes in groups.items():
        frames = [takes[t] for t in sorted(takes)]
        order = np.unique(np.linspace(0, len(frames) - 1, min(per_class, len(frames))).round().astype(int))
        picked: list = []
        for frac in (0.5, 0.0, 1.0, 0.25, 0.75):
            for g in order:
                i = frames[g][int(round((len(frames[g]) - 1) * frac))]
                if len(picked) < per_class and i not in picked:
                    picked.append(i)
        chosen[cid] = sorted(picked)
    return chosen


def write_contact_sheet(bag: Path, records: list, path: Path, per_class: int = 4) -> None:
    """Read the chosen frames back from the bag and write the PNG: rows = the six classes
    then background, columns = frames (:func:`select_sheet_frames`)."""
    from hmocap_ros.io.bag_reader import BagReader
    from hmocap_ros.io.conversions import image_to_numpy

    chosen = select_sheet_frames(records, per_class)
    by_stamp = {records[i]["stamp_ns"]: records[i] for ids in chosen.values() for i in ids}
    tiles = {}
    with BagReader(bag) as reader:
        for m in reader.messages([topics.DEPTH_IMAGE]):
            r = by_stamp.get(m.log_time_ns)
            if r is None:
                continue
            gt = GroundTruth(r["class_id"], r["name"], r["u"], r["v"], r["position"], r["visible"])
            caption = f"{r['class_id']} {r['name']}" if r["class_id"] else f"0 background: {r['kind']}"
            tiles[r["index"]] = contact_tile(image_to_numpy(m.msg), gt, f"{caption}  #{r['index']}")
    columns = max([len(v) for v in chosen.values()] + [1])
    blank = np.zeros((TILE[1], TILE[0], 3), np.uint8)
    rows = []
    for cid in list(range(1, len(gs.GESTURE_CLASSES) + 1)) + [0]:
        row = [tiles[i] for i in chosen.get(cid, [])]
        rows.append(np.hstack(row + [blank] * (columns - len(row))))
    sheet = np.vstack(rows)
    for x in range(1, columns):
        sheet[:, x * TILE[0]] = 255
    for y in range(1, len(rows)):
        sheet[y * TILE[1]] = 255
    cv2.imwrite(str(path), sheet, [cv2.IMWRITE_PNG_COMPRESSION, 9])


# ---------------------------------------------------------------------------------------
# Generation
# ---------------------------------------------------------------------------------------


@dataclass
class Summary:
    frames: int
    per_class: dict
    visible: int
    seconds: float
    bag_bytes: int
    labels_path: Path
    contact_path: Path | None


def generate(out: str | Path, *, seed: int = 0, subjects: int = 2, frames: int = 200,
             width: int = 640, height: int = 480, subject_offset: int = 0, fps: float = 10.0,
             contact: bool = True, progress: bool = True, per_class: int = 4,
             hold: tuple = HOLD_FRAMES, background: str = "room") -> Summary:
    """Render and write the bag, its labels JSON and (optionally) its contact sheet."""
    if subjects < 1 or frames < 1 or width < 16 or height < 16 or fps <= 0:
        raise ValueError("subjects and frames must be >= 1, the image at least 16x16, fps > 0")
    if not 1 <= hold[0] <= hold[1]:
        raise ValueError(f"hold frames must satisfy 1 <= min <= max, got {hold}")
    from tqdm import tqdm

    t0 = time.perf_counter()
    out = Path(out)
    labels_path, contact_path = sidecar_paths(out)
    model = load_body_model("hands")
    factory = RosbagsFactory()
    rng = np.random.default_rng([seed, _STREAM_POSES])
    noise_rng = np.random.default_rng([seed, _STREAM_NOISE])
    schedule = _schedule(rng)
    period = int(round(1e9 / fps))
    splits = np.diff(np.linspace(0, frames, subjects + 1).round().astype(int))
    records, layouts_info, subjects_info = [], {}, {}
    stamp = START_NS
    index = take = 0
    layout_id = -1
    bar = tqdm(total=frames, file=sys.stderr, disable=not progress, unit="frame", desc="gestures")
    with whole_bag(out) as bag:
        for k, n_frames in enumerate(splits):
            subject_id = subject_offset + k
            actor = Actor(gs.make_subject(model, subject_id))
            subjects_info[str(subject_id)] = {
                "height_m": round(actor.subject.height, 4),
                "bone_scale": np.round(actor.subject.shape.bone_scale, 4).tolist(),
                "radial_scale": np.round(actor.subject.shape.radial_scale, 4).tolist(),
                "global_scale": round(float(actor.subject.shape.global_scale), 4),
                "entity_names": list(actor.subject.shape.entity_names)}
            done = 0
            takes_here = TAKES_PER_LAYOUT
            while done < n_frames:
                if takes_here >= TAKES_PER_LAYOUT:
                    layout_id += 1
                    layout = make_layout(np.random.default_rng([seed, _STREAM_LAYOUT, layout_id]),
                                         layout_id, width, height, background=background)
                    layout_rng = np.random.default_rng([seed, _STREAM_LAYOUT, layout_id, 1])
                    people = [Actor(gs.make_subject(model, int(layout_rng.integers(10**6, 10**9))))
                              for _ in layout.bystanders]
                    cam = layout.camera
                    layouts_info[str(layout_id)] = {
                        "camera_position": np.round(cam.position, 4).tolist(),
                        "camera_quaternion_xyzw": np.round(cam.pose_quaternion(), 6).tolist(),
                        "zone_xz_radius": [round(float(x), 4) for x in layout.zone],
                        "furniture": [[kind, round(x, 3), round(z, 3)] for kind, x, z, _ in layout.items],
                        "bystanders": len(people)}
                    actor.params = None
                    takes_here = 0
                    if index:
                        stamp += 10 * period  # a cut: 1 s gap at 10 fps
                kind = next(schedule)
                states = _take_frames(model, actor, kind, layout, rng, take, hold)
                targets = [_bystander_pose(model, person, spot, layout, layout_rng)
                           for person, spot in zip(people, layout.bystanders)]
                starts = [p.params if p.params is not None else t for p, t in zip(people, targets)]
                n_trans = sum(s.phase == "transition" for s in states)
                for i, state in enumerate(states[: n_frames - done]):
                    t = min(1.0, (i + 1) / (n_trans + 1)) if n_trans else 1.0
                    for person, a, b in zip(people, starts, targets):
                        person.params = _lerp_pose(model, a, b, t)
                    actor.params = state.params
                    meshes = [(layout.vertices, layout.faces)]
                    meshes += [(p.vertices(model), model.faces) for p in people]
                    meshes.append((actor.vertices(model), model.faces))
                    render = render_depth(cam, meshes, noise_rng)
                    face_range = (int(render.face_offsets[-2]), int(render.face_offsets[-1]))
                    gt = ground_truth(model, actor, state, layout, render, face_range)
                    bag.write(topics.DEPTH_IMAGE, numpy_to_image(render.depth_mm, "16UC1", stamp,
                                                                 cam.frame_id, factory), stamp)
                    bag.write(topics.DEPTH_INFO, dict_to_camera_info(cam.to_camera_info_dict(), stamp,
                                                                     factory), stamp)
                    bag.write(topics.GT_GESTURES, gesture_array(factory, stamp, cam.frame_id, gt), stamp)
                    pelvis = state.params[model.skeleton.translation_dofs]
                    records.append({
                        "index": index, "stamp_ns": stamp, "subject": subject_id, "layout": layout_id,
                        "take": take, "phase": state.phase, "kind": state.kind, "class_id": gt.class_id,
                        "name": gt.name, "side": state.side if gt.class_id else "",
                        "u": None if gt.u is None else round(gt.u, 3),
                        "v": None if gt.v is None else round(gt.v, 3),
                        "position": None if gt.position is None else [round(c, 4) for c in gt.position],
                        "visible": gt.visible,
                        "distance_m": round(float(np.linalg.norm(cam.world_to_camera(pelvis))), 3)})
                    index += 1
                    done += 1
                    stamp += period
                    bar.update(1)
                take += 1
                takes_here += 1
    bar.close()
    per_cls = {name: sum(r["class_id"] == i for r in records)
               for i, name in enumerate(("background",) + gs.GESTURE_CLASSES)}
    cam_info = {"frame_id": cam.frame_id, "width": width, "height": height,
                "K": np.round(cam.K, 6).tolist(), "depth_unit": "mm", "invalid": 0}
    labels = {"format": LABELS_FORMAT, "bag": out.name, "seed": seed, "subject_offset": subject_offset,
              "fps": fps, "background": background, "classes": {str(i + 1): n for i, n in enumerate(gs.GESTURE_CLASSES)},
              "reference_points": gs.REFERENCE_POINTS, "camera": cam_info,
              "subjects": subjects_info, "layouts": layouts_info, "counts": per_cls, "frames": records}
    labels_path.write_text(json.dumps(labels, indent=1) + "\n")
    if contact:
        write_contact_sheet(out, records, contact_path, per_class)
    return Summary(len(records), per_cls, sum(r["visible"] for r in records), time.perf_counter() - t0,
                   out.stat().st_size if out.is_file() else sum(p.stat().st_size for p in out.rglob("*")),
                   labels_path, contact_path if contact else None)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", required=True, help="bag to write (.mcap file, or a rosbag2 folder)")
    parser.add_argument("--seed", type=int, default=0, help="random seed: rooms, poses, noise (default 0)")
    parser.add_argument("--subjects", type=int, default=2, help="number of subjects (default 2)")
    parser.add_argument("--subject-offset", type=int, default=0,
                        help="identity of the first subject; use disjoint ranges for train and test (default 0)")
    parser.add_argument("--frames", type=int, default=200, help="number of depth frames (default 200)")
    parser.add_argument("--width", type=int, default=640, help="image width (default 640)")
    parser.add_argument("--height", type=int, default=480, help="image height (default 480)")
    parser.add_argument("--fps", type=float, default=10.0, help="frame rate of the stamps (default 10)")
    parser.add_argument("--hold", type=int, nargs=2, default=list(HOLD_FRAMES), metavar=("MIN", "MAX"),
                        help=f"frames per take, drawn in [MIN, MAX] (default {HOLD_FRAMES[0]} {HOLD_FRAMES[1]})")
    parser.add_argument("--background", choices=BACKGROUNDS, default="room",
                        help="room: back wall 0.4-2.3 m behind the person (default); close: 0.15-0.85 m")
    parser.add_argument("--no-contact-sheet", action="store_true", help="do not write BAG.contact.png")
    parser.add_argument("--force", action="store_true", help="overwrite the bag and its side files")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def main_from_args(ns) -> int:
    out = Path(ns.out)
    labels_path, contact_path = sidecar_paths(out)
    if out.exists():
        if not ns.force:
            print(f"error: {out} exists (use --force to overwrite)", file=sys.stderr)
            return 2
        shutil.rmtree(out) if out.is_dir() else out.unlink()
        for p in (labels_path, contact_path):
            p.unlink(missing_ok=True)
    try:
        s = generate(out, seed=ns.seed, subjects=ns.subjects, frames=ns.frames, width=ns.width,
                     height=ns.height, subject_offset=ns.subject_offset, fps=ns.fps,
                     contact=not ns.no_contact_sheet, progress=not ns.quiet, hold=tuple(ns.hold),
                     background=ns.background)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    counts = ", ".join(f"{k} {v}" for k, v in s.per_class.items())
    print(f"{out}: {s.frames} frames ({counts}); {s.visible} labelled frames with a visible reference "
          f"point; {s.bag_bytes / 1e6:.2f} MB; {s.seconds:.1f} s ({s.frames / s.seconds:.1f} frames/s)")
    print(f"labels: {s.labels_path}")
    if s.contact_path:
        print(f"contact sheet: {s.contact_path}")
    return 0
