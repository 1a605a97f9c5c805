"""Forest files: a compact, versioned, pickle-free format for offline and online gesture forests.

A forest file is a NumPy ``.npz`` archive (``np.savez_compressed``; read with
``allow_pickle=False``, so loading never runs code) holding plain numeric arrays:

=====================  =================  ==========================================================
 name                   shape / dtype      content
=====================  =================  ==========================================================
 ``header``             (B,) uint8         UTF-8 JSON header (below)
 ``tree_offsets``       (M+1,) int64       tree ``m`` owns nodes ``tree_offsets[m]:tree_offsets[m+1]``
 ``feature``            (N, 4) float32     test offsets u_x, u_y, v_x, v_y [pixel*metre]
 ``threshold``          (N,) float32       go left when f < threshold
 ``left``, ``right``    (N,) int32         children, tree-local node index; -1 at a leaf
 ``counts``             (N, C) float32     class statistics per node (leaf histograms)
 ``depth``              (N,) int16         node depth, root 0
 ``pending_offsets``    (M+1,) int64       tree ``m`` owns pending rows ``pending_offsets[m]:[m+1]``
 ``pending_node``       (P,) int32         online trees: the unsplit leaf of each pending row
 ``pending_feature``    (P, K, 4) float32  its K candidate tests
 ``pending_threshold``  (P, K) float32     their thresholds
 ``pending_counts``     (P, K, 2, C) f32   class statistics left / right of each candidate
=====================  =================  ==========================================================

Header keys: ``format`` = ``"hmocap-forest"``, ``version`` (integer; this module reads
versions 1 and 2 and refuses newer ones; version 2 added ``features.outside``, version 1
files read as ``outside = "background"``), ``kind`` (``"offline"`` or ``"online"``), ``class_names``
(class 0 is background), ``depth_unit`` = ``"m"`` (tests and thresholds are in metres,
whatever the camera's raw unit), ``features`` (``FeatureParams``: ``feature_type``
``"clipped"``/``"plain"``, ``kappa_m``, ``patch_half_size_px_m``, ``background_depth_m``, ``outside``,
plus ``offset_unit`` = ``"pixel*metre"``), ``n_trees``, ``n_nodes``, ``n_pending_tests`` (K),
``created_utc`` and ``meta`` (free JSON: training parameters, data, timings).

Offline forests have no pending rows (P = 0, K = 0); online forests keep, per unsplit leaf,
the statistics alg. 6 needs to decide splits, so an online forest saved and loaded keeps
growing where it stopped (sec. 3.4.2). Any unreadable, truncated, corrupt, inconsistent or
incompatible file raises :class:`ForestFileError`.
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import os
import tempfile
import zipfile
import zlib
from pathlib import Path

import numpy as np

from hmocap_ros.gestures.params import FeatureParams
from hmocap_ros.gestures.trees import Forest, PendingTests, Tree

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "ForestFileError", "load_forest", "read_header", "save_forest"]

FORMAT_NAME = "hmocap-forest"
FORMAT_VERSION = 2

# name -> (dtype, trailing shape with C = classes, K = pending tests); leading dim is N or P.
_NODE_ARRAYS = {
    "feature": (np.float32, (4,)),
    "threshold": (np.float32, ()),
    "left": (np.int32, ()),
    "right": (np.int32, ()),
    "counts": (np.float32, ("C",)),
    "depth": (np.int16, ()),
}
_PENDING_ARRAYS = {
    "pending_node": (np.int32, ()),
    "pending_feature": (np.float32, ("K", 4)),
    "pending_threshold": (np.float32, ("K",)),
    "pending_counts": (np.float32, ("K", 2, "C")),
}


class ForestFileError(ValueError):
    """A forest file cannot be used: unreadable, truncated, corrupt, inconsistent or incompatible."""


def _json_default(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if dataclasses.is_dataclass(obj):
        return dataclasses.asdict(obj)
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def save_forest(forest: Forest, path) -> Path:
    """Write ``forest`` to ``path`` (atomically: a temporary file renamed into place). Returns the path."""
    path = Path(path)
    n_classes = forest.n_classes
    for m, tree in enumerate(forest.trees):
        try:
            tree.validate(n_classes)
        except ValueError as err:
            raise ValueError(f"tree {m} is not valid: {err}") from err
    ks = {t.pending.n_tests for t in forest.trees if t.pending is not None and t.pending.node.size}
    if len(ks) > 1:
        raise ValueError("all online trees must keep the same number of candidate tests")
    k = ks.pop() if ks else 0
    pendings = [t.pending if t.pending is not None and t.pending.node.size else PendingTests.empty(k, n_classes)
                for t in forest.trees]
    features = dataclasses.asdict(forest.features)
    features["offset_unit"] = "pixel*metre"
    header = {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "kind": forest.kind,
        "class_names": list(forest.class_names),
        "depth_unit": "m",
        "features": features,
        "n_trees": len(forest.trees),
        "n_nodes": forest.n_nodes,
        "n_pending_tests": k,
        "created_utc": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "meta": forest.meta,
    }
    arrays: dict[str, np.ndarray] = {
        "header": np.frombuffer(json.dumps(header, default=_json_default).encode("utf-8"), np.uint8),
        "tree_offsets": np.concatenate([[0], np.cumsum([t.n_nodes for t in forest.trees])]).astype(np.int64),
        "pending_offsets": np.concatenate([[0], np.cumsum([p.node.size for p in pendings])]).astype(np.int64),
    }
    for name, (dtype, _) in _NODE_ARRAYS.items():
        arrays[name] = np.concatenate([np.asarray(getattr(t, name), dtype) for t in forest.trees])
    for name, (dtype, _) in _PENDING_ARRAYS.items():
        field = name.removeprefix("pending_")
        arrays[name] = np.concatenate([np.asarray(getattr(p, field), dtype) for p in pendings])
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez_compressed(fh, allow_pickle=False, **arrays)  # numeric arrays only
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def _read(path: Path):
    """(header dict, archive arrays dict) of a forest file; ForestFileError on any read problem."""
    try:
        with open(path, "rb") as fh:
            magic = fh.read(4)
        if magic != b"PK\x03\x04":
            what = "an empty file" if not magic else "not an .npz archive"
            raise ForestFileError(f"{path}: not a forest file ({what})")
        with np.load(path, allow_pickle=False) as archive:
            if "header" not in archive.files:
                raise ForestFileError(f"{path}: not a forest file (no header)")
            header = json.loads(archive["header"].tobytes().decode("utf-8"))
            if not isinstance(header, dict) or header.get("format") != FORMAT_NAME:
                raise ForestFileError(f"{path}: not a forest file (format is not {FORMAT_NAME!r})")
            version = header.get("version")
            if not isinstance(version, int) or version < 1:
                raise ForestFileError(f"{path}: invalid format version {version!r}")
            if version > FORMAT_VERSION:
                raise ForestFileError(f"{path}: forest file version {version} is newer than this reader "
                                      f"(version {FORMAT_VERSION}); update hmocap_ros")
            missing = [n for n in ["tree_offsets", "pending_offsets", *_NODE_ARRAYS, *_PENDING_ARRAYS]
                       if n not in archive.files]
            if missing:
                raise ForestFileError(f"{path}: truncated forest file, missing arrays {missing}")
            arrays = {n: archive[n] for n in archive.files if n != "header"}
    except ForestFileError:
        raise
    except FileNotFoundError as err:
        raise ForestFileError(f"{path}: no such forest file") from err
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, zlib.error, UnicodeDecodeError) as err:
        raise ForestFileError(f"{path}: truncated, corrupt or unreadable forest file "
                              f"({type(err).__name__}: {err})") from err
    return header, arrays


def read_header(path) -> dict:
    """The JSON header of a forest file (class names, features, meta) without building the trees."""
    return _read(Path(path))[0]


def _typed(arrays: dict, name: str, dtype, shape: tuple, path: Path) -> np.ndarray:
    a = arrays[name]
    want = np.dtype(dtype).kind
    ok_kind = a.dtype.kind == want or (want == "i" and a.dtype.kind == "u")
    if not ok_kind or a.shape != shape:
        raise ForestFileError(f"{path}: array {name} is {a.dtype}{a.shape}, expected {np.dtype(dtype)}{shape}")
    return a.astype(dtype, copy=False)


def _offsets(arrays, name, n_trees, total_name, path) -> np.ndarray:
    off = _typed(arrays, name, np.int64, (n_trees + 1,), path)
    total = arrays[total_name].shape[0]
    if off[0] != 0 or off[-1] != total or np.any(np.diff(off) < 0):
        raise ForestFileError(f"{path}: {name} does not partition the {total} rows of {total_name}")
    return off


def load_forest(path) -> Forest:
    """Read a forest file written by :func:`save_forest` (any version up to ``FORMAT_VERSION``)."""
    path = Path(path)
    header, arrays = _read(path)
    try:
        kind = header["kind"]
        class_names = tuple(header["class_names"])
        if not all(isinstance(c, str) for c in class_names) or len(class_names) < 2:
            raise ForestFileError(f"{path}: class_names must be at least two strings")
        feat = {k: v for k, v in header["features"].items() if k != "offset_unit"}
        if header["features"].get("offset_unit", "pixel*metre") != "pixel*metre":
            raise ForestFileError(f"{path}: unsupported offset unit {header['features']['offset_unit']!r}")
        if header.get("depth_unit", "m") != "m":
            raise ForestFileError(f"{path}: unsupported depth unit {header['depth_unit']!r}")
        if header["version"] < 2:  # version 1 probed "far background" outside the image
            feat.setdefault("outside", "background")
        features = FeatureParams(**feat)
        n_trees, n_nodes, k = int(header["n_trees"]), int(header["n_nodes"]), int(header["n_pending_tests"])
        meta = header.get("meta", {})
    except ForestFileError:
        raise
    except (KeyError, TypeError, ValueError, AttributeError) as err:
        raise ForestFileError(f"{path}: invalid forest header ({type(err).__name__}: {err})") from err
    if n_trees < 1:
        raise ForestFileError(f"{path}: forest has no trees")
    c = len(class_names)
    node = {}
    for name, (dtype, tail) in _NODE_ARRAYS.items():
        node[name] = _typed(arrays, name, dtype, (n_nodes,) + tuple(c if t == "C" else t for t in tail), path)
    n_pending = arrays["pending_node"].shape[0] if arrays["pending_node"].ndim == 1 else -1
    pend = {}
    for name, (dtype, tail) in _PENDING_ARRAYS.items():
        shape = (n_pending,) + tuple(c if t == "C" else k if t == "K" else t for t in tail)
        pend[name] = _typed(arrays, name, dtype, shape, path)
    tree_off = _offsets(arrays, "tree_offsets", n_trees, "left", path)
    pend_off = _offsets(arrays, "pending_offsets", n_trees, "pending_node", path)
    trees = []
    for m in range(n_trees):
        a, b = tree_off[m], tree_off[m + 1]
        pa, pb = pend_off[m], pend_off[m + 1]
        pending = None
        if kind == "online" or pb > pa:
            pending = PendingTests(*(pend[f"pending_{f}"][pa:pb].copy()
                                     for f in ("node", "feature", "threshold", "counts")))
        tree = Tree(**{f: node[f][a:b].copy() for f in _NODE_ARRAYS}, pending=pending)
        try:
            tree.validate(c)
        except ValueError as err:
            raise ForestFileError(f"{path}: tree {m} is corrupt: {err}") from err
        trees.append(tree)
    try:
        return Forest(trees, class_names, features, kind, meta if isinstance(meta, dict) else {})
    except ValueError as err:
        raise ForestFileError(f"{path}: {err}") from err
