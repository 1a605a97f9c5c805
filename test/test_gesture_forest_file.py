"""The forest file format: round trips (offline and online forests) and clear errors for bad files."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest
from fixtures.toy_depth import toy_detector_params, toy_forest, toy_frame

from hmocap_ros.gestures import (
    FeatureParams,
    Forest,
    ForestFileError,
    GestureDetector,
    PendingTests,
    Tree,
    load_forest,
    read_header,
    save_forest,
)
from hmocap_ros.gestures.forest_file import FORMAT_NAME, FORMAT_VERSION

SHAPE = (240, 320)
TREE_ARRAYS = ("feature", "threshold", "left", "right", "counts", "depth")


def online_forest() -> Forest:
    """A small online-style forest: a split root whose leaves keep candidate tests and statistics."""
    rng = np.random.default_rng(0)
    trees = []
    for _ in range(3):
        tree = Tree(feature=rng.uniform(-40, 40, (3, 4)).astype(np.float32),
                    threshold=rng.uniform(-0.2, 0.2, 3).astype(np.float32),
                    left=np.array([1, -1, -1], np.int32), right=np.array([2, -1, -1], np.int32),
                    counts=rng.uniform(0, 30, (3, 4)).astype(np.float32), depth=np.array([0, 1, 1], np.int16))
        tree.pending = PendingTests(node=np.array([1, 2], np.int32),
                                    feature=rng.uniform(-40, 40, (2, 5, 4)).astype(np.float32),
                                    threshold=rng.uniform(-0.2, 0.2, (2, 5)).astype(np.float32),
                                    counts=rng.uniform(0, 9, (2, 5, 2, 4)).astype(np.float32))
        trees.append(tree)
    trees[2] = Tree.single_leaf([3, 1, 0, 2])  # a tree that has not split yet
    trees[2].pending = PendingTests.empty(5, 4)
    return Forest(trees, ("background", "tee", "pause", "ok"), FeatureParams(kappa_m=0.3), "online",
                  {"note": "test", "alpha": 300})


def rewrite(src, dst, **changes):
    """Copy forest file ``src`` to ``dst`` with arrays replaced (None removes one)."""
    with np.load(src, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    for key, value in changes.items():
        if value is None:
            arrays.pop(key)
        else:
            arrays[key] = value
    np.savez(dst, **arrays)
    return dst


def header_bytes(header: dict) -> np.ndarray:
    return np.frombuffer(json.dumps(header).encode(), np.uint8)


def test_offline_round_trip_gives_identical_trees_and_detections(tmp_path):
    forest = toy_forest(shape=SHAPE)
    path = save_forest(forest, tmp_path / "sub" / "toy.forest.npz")
    assert path.exists() and not list(path.parent.glob("*.tmp"))
    loaded = load_forest(path)
    assert loaded.class_names == forest.class_names and loaded.kind == "offline"
    assert loaded.features == forest.features
    assert loaded.meta["training"]["trees"] == forest.meta["training"]["trees"]
    for a, b in zip(forest.trees, loaded.trees):
        for name in TREE_ARRAYS:
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
            assert getattr(a, name).dtype == getattr(b, name).dtype
        assert b.pending is None

    rng = np.random.default_rng(2)
    frames = [toy_frame(rng, SHAPE, c)[0] for c in (1, 2, 0)]
    runs = []
    for f in (forest, loaded):
        det = GestureDetector(f, toy_detector_params(SHAPE))
        runs.append([det.update(frame, k) for k, frame in enumerate(frames)] + [det.density])
    assert runs[0][:-1] == runs[1][:-1]
    np.testing.assert_array_equal(runs[0][-1], runs[1][-1])

    header = read_header(path)
    assert header["format"] == FORMAT_NAME and header["version"] == FORMAT_VERSION
    assert header["features"]["feature_type"] == "clipped" and header["features"]["offset_unit"] == "pixel*metre"
    assert header["depth_unit"] == "m" and header["n_trees"] == 8


def test_online_forest_keeps_its_pending_statistics(tmp_path):
    forest = online_forest()
    loaded = load_forest(save_forest(forest, tmp_path / "online.npz"))
    assert loaded.kind == "online" and loaded.meta == {"note": "test", "alpha": 300}
    assert loaded.features.kappa_m == 0.3
    for a, b in zip(forest.trees, loaded.trees):
        for name in TREE_ARRAYS:
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        for name in ("node", "feature", "threshold", "counts"):
            np.testing.assert_array_equal(getattr(a.pending, name), getattr(b.pending, name))
    assert loaded.trees[2].n_nodes == 1 and loaded.trees[2].pending.node.size == 0
    assert read_header(tmp_path / "online.npz")["n_pending_tests"] == 5


@pytest.fixture()
def good_file(tmp_path):
    return save_forest(online_forest(), tmp_path / "good.npz")


def test_truncated_and_corrupted_files_raise_forest_file_error(tmp_path, good_file):
    data = good_file.read_bytes()
    cases = {
        "truncated": data[: len(data) // 2],
        "tail_cut": data[:-10],
        "empty": b"",
        "text": b"not a forest at all\n",
        "flipped": data[:200] + bytes(b ^ 0xFF for b in data[200:400]) + data[400:],
    }
    for name, blob in cases.items():
        path = tmp_path / f"{name}.npz"
        path.write_bytes(blob)
        with pytest.raises(ForestFileError):
            load_forest(path)
    with pytest.raises(ForestFileError, match="no such"):
        load_forest(tmp_path / "missing.npz")
    np.save(tmp_path / "single.npy", np.zeros(3))
    with pytest.raises(ForestFileError):
        load_forest(tmp_path / "single.npy")


def test_incompatible_or_inconsistent_files_raise_forest_file_error(tmp_path, good_file):
    header = read_header(good_file)
    with np.load(good_file) as z:
        left = z["left"].copy()
        counts = z["counts"].copy()

    def bad_header(**kw):
        return header_bytes({**header, **kw})

    cases = {
        "format": dict(header=bad_header(format="someone-elses-forest")),
        "newer": dict(header=bad_header(version=FORMAT_VERSION + 1)),
        "header_json": dict(header=np.frombuffer(b"{not json", np.uint8)),
        "features": dict(header=bad_header(features={"feature_type": "magic"})),
        "classes": dict(header=bad_header(class_names=["only_one"])),
        "n_nodes": dict(header=bad_header(n_nodes=header["n_nodes"] + 1)),
        "missing_array": dict(threshold=None),
        "no_header": dict(header=None),
        "child_range": dict(left=np.where(left > 0, left + 100, left)),
        "cycle": dict(left=np.where(left > 0, 0, left)),
        "counts_shape": dict(counts=counts[:, :2].copy()),
        "negative_counts": dict(counts=-counts),
        "float_links": dict(left=left.astype(np.float32)),
        "pickled": dict(feature=np.array([object()] * 3, dtype=object)),
    }
    for name, change in cases.items():
        path = tmp_path / f"{name}.npz"
        if name == "pickled":
            with np.load(good_file) as z:
                arrays = {k: z[k] for k in z.files}
            arrays.update(change)
            np.savez(path, **arrays)  # an object array is pickled inside the archive
        else:
            rewrite(good_file, path, **change)
        with pytest.raises(ForestFileError) as err:
            load_forest(path)
        assert str(path) in str(err.value), name
    with zipfile.ZipFile(good_file) as z:
        assert all(not n.endswith(".pkl") for n in z.namelist())


def test_saving_an_invalid_forest_is_refused(tmp_path):
    forest = online_forest()
    forest.trees[0].left[0] = 7
    with pytest.raises(ValueError):
        save_forest(forest, tmp_path / "bad.npz")
    assert not (tmp_path / "bad.npz").exists()
