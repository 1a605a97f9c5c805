"""Offline forest training: information gain splits (eq. 3.2), a learnable toy problem, boosted
tree-by-tree learning with out-of-bag misclassified samples (sec. 3.2.3), determinism."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from fixtures.toy_depth import TOY_CLASSES, toy_forest, toy_sequence, toy_train_params

from hmocap_ros.gestures import (
    FeatureParams,
    ForestParams,
    SampleSet,
    collect_samples,
    grow_tree,
    train_forest,
    train_forest_on_samples,
)
from hmocap_ros.gestures.forest import balanced_error, frames_to_metres
from hmocap_ros.gestures.patches import mine_hard_negatives
from hmocap_ros.gestures.tree_growth import information_gain
from hmocap_ros.gestures.trees import apply_tree

SHAPE = (240, 320)


def edge_problem():
    """Class 1 pixels sit 4-10 px left of a step to 2.5 m; class 0 pixels on flat 2 m floor."""
    img = np.full((1, 40, 200), 2.0, np.float32)
    img[0, :, 100:] = 2.5
    ys, xs = np.mgrid[5:35, 90:96]
    ys0, xs0 = np.mgrid[5:35, 20:26]
    x = np.concatenate([xs.ravel(), xs0.ravel()]).astype(np.int32)
    y = np.concatenate([ys.ravel(), ys0.ravel()]).astype(np.int32)
    label = np.concatenate([np.ones(xs.size), np.zeros(xs0.size)]).astype(np.int32)
    return SampleSet(img, np.zeros(x.size, np.int32), x, y, label, 2)


def test_one_split_separates_a_separable_pair_with_full_information_gain():
    s = edge_problem()
    params = ForestParams(max_depth=1, n_tests=200, n_thresholds=16, min_samples_leaf=1)
    tree = grow_tree(s, np.arange(len(s)), params, FeatureParams(), np.random.default_rng(0))
    assert tree.n_nodes == 3 and tree.left[0] == 1 and tree.right[0] == 2
    np.testing.assert_array_equal(tree.counts[0], [180, 180])
    # Both children pure: the gain is the parent entropy ln 2 (eq. 3.2 at its maximum).
    for child in (1, 2):
        assert np.count_nonzero(tree.counts[child]) == 1
    split = np.stack([tree.counts[1], tree.counts[2]])
    assert information_gain(split) == pytest.approx(np.log(2.0))
    leaves = apply_tree(tree, FeatureParams(), s.frames, s.frame, s.x, s.y)
    np.testing.assert_array_equal(tree.leaf_proba()[leaves].argmax(1), s.label)


def test_information_gain_of_eq_3_2():
    ln2 = np.log(2.0)
    counts = np.array([[[10, 0], [0, 10]],     # perfect split of a balanced pair: H(parent) = ln 2
                       [[5, 5], [5, 5]],       # no information
                       [[0, 0], [4, 4]],       # empty side
                       [[3, 1], [1, 3]]], float)
    h = -(0.75 * np.log(0.75) + 0.25 * np.log(0.25))
    np.testing.assert_allclose(information_gain(counts), [ln2, 0.0, 0.0, ln2 - h], atol=1e-12)
    assert information_gain(np.ones((7, 5, 2, 3))).shape == (7, 5)  # online (P, K, 2, C) statistics


def test_tree_respects_depth_and_leaf_size_limits():
    s = edge_problem()
    rng = np.random.default_rng(1)
    s.label = rng.integers(0, 2, len(s)).astype(np.int32)  # noise: the tree grows as far as allowed
    params = ForestParams(max_depth=4, min_samples_leaf=7)
    tree = grow_tree(s, rng.integers(0, len(s), len(s)), params, FeatureParams(), rng)
    tree.validate(2)
    assert tree.max_depth <= 4
    leaf_sizes = tree.counts[tree.is_leaf].sum(1)
    assert leaf_sizes.min() >= 7
    assert tree.counts[tree.is_leaf].sum() == len(s)  # every bag sample ends in one leaf


@pytest.fixture(scope="module")
def held_out():
    rng = np.random.default_rng(99)
    frames, labels = toy_sequence(rng, 60, SHAPE)
    params = toy_train_params(SHAPE)
    return collect_samples(frames_to_metres(frames, params), labels, params.patches, params.features, rng, 3)


def test_forest_learns_the_toy_gestures(held_out):
    forest = toy_forest(shape=SHAPE)
    assert forest.class_names == TOY_CLASSES and len(forest.trees) == 8
    proba = forest.predict_proba(held_out.frames, held_out.frame, held_out.x, held_out.y)
    np.testing.assert_allclose(proba.sum(1), 1.0, atol=1e-5)  # eq. 3.1: a mean of distributions
    predicted = proba.argmax(1)
    accuracy = np.mean(predicted == held_out.label)
    assert accuracy > 0.95, accuracy
    assert balanced_error(held_out.label, predicted, 3) < 0.05


def test_boosted_training_reports_and_improves_the_out_of_bag_error():
    forest = toy_forest(shape=SHAPE)
    trees = forest.meta["training"]["trees"]
    assert forest.meta["training"]["method"] == "boosted"
    assert trees[0]["n_carried"] == 0
    # Sec. 3.2.3: misclassified out-of-bag samples of a tree join the next tree's bag ...
    assert all(t["n_carried"] > 0 for t in trees[1:])
    assert all(t["bag_size"] >= 3 * 5000 for t in trees)  # ... on top of a balanced bag
    first, last = trees[0]["forest_oob_error"], trees[-1]["forest_oob_error"]
    assert last < first, (first, last)
    assert forest.meta["training"]["bag_samples_per_s"] > 0


def test_bagged_training_carries_nothing_and_progress_is_reported():
    rng = np.random.default_rng(4)
    frames, labels = toy_sequence(rng, 30, SHAPE)
    params = toy_train_params(SHAPE, n_trees=3, max_depth=8, samples_per_class=500)
    params = dataclasses.replace(params, forest=ForestParams(n_trees=3, max_depth=8, samples_per_class=500,
                                                             boosted=False, mining_rounds=0))
    reports = []
    forest = train_forest(frames, labels, params, rng, class_names=TOY_CLASSES, progress=reports.append)
    assert [r.index for r in reports] == [0, 1, 2]
    assert all(r.n_carried == 0 and r.bag_size == 1500 for r in reports)
    assert forest.meta["training"]["method"] == "bagged"
    assert forest.meta["training"]["n_frames"] == 30


def test_hard_negative_mining_adds_the_forests_false_positives_and_retrains():
    rng = np.random.default_rng(6)
    frames, labels = toy_sequence(rng, 40, SHAPE)
    params = toy_train_params(SHAPE, n_trees=3, max_depth=6, samples_per_class=300, mining_rounds=1)
    reports = []
    forest = train_forest(frames, labels, params, rng, class_names=TOY_CLASSES, progress=reports.append)
    assert [r.index for r in reports] == [0, 1, 2, 0, 1, 2]  # two forests: before and after mining
    rounds = forest.meta["training"]["rounds"]
    assert len(rounds) == 2 and rounds[1]["mined_negatives"] > 0
    mined = rounds[1]["mined_negatives"]
    assert rounds[1]["n_samples"] == rounds[0]["n_samples"] + mined
    assert rounds[1]["class_counts"][0] == rounds[0]["class_counts"][0] + mined  # all background
    assert rounds[1]["class_counts"][1:] == rounds[0]["class_counts"][1:]

    # The mined pixels are where a forest votes for a gesture away from the annotated one.
    shallow = train_forest(frames, labels, dataclasses.replace(params, forest=dataclasses.replace(
        params.forest, mining_rounds=0)), np.random.default_rng(0), class_names=TOY_CLASSES)
    metres = frames_to_metres(frames, params)
    negatives = mine_hard_negatives(shallow, metres, labels, params.patches, np.random.default_rng(0), 50, 4)
    assert len(negatives) > 0 and np.all(negatives.label == 0)
    assert np.bincount(negatives.frame, minlength=len(frames)).max() <= 50
    proba = shallow.predict_proba(metres, negatives.frame, negatives.x, negatives.y)
    assert np.all(proba[:, 1:].max(1) > proba[:, 0])  # each one votes for a gesture
    lab = np.array([(0, -1, -1) if lab is None else lab for lab in labels])[negatives.frame]
    d = metres[negatives.frame, lab[:, 2].clip(0), lab[:, 1].clip(0)]
    away = 2.0 * params.patches.box_half_size_px_m / d
    far = (np.abs(negatives.x - lab[:, 1]) > away) | (np.abs(negatives.y - lab[:, 2]) > away)
    assert np.all(far | (lab[:, 0] == 0))


def test_training_repeats_bit_for_bit_with_the_seed():
    def train(seed):
        rng = np.random.default_rng(seed)
        frames, labels = toy_sequence(np.random.default_rng(5), 20, SHAPE)
        params = toy_train_params(SHAPE, n_trees=2, max_depth=10, samples_per_class=400)
        return train_forest(frames, labels, params, rng)

    a, b, c = train(1), train(1), train(2)
    for ta, tb in zip(a.trees, b.trees):
        for name in ("feature", "threshold", "left", "right", "counts", "depth"):
            np.testing.assert_array_equal(getattr(ta, name), getattr(tb, name))
    assert not np.array_equal(a.trees[0].feature, c.trees[0].feature)
    assert a.class_names == ("background", "gesture_1", "gesture_2")


def test_bad_training_input_is_refused():
    rng = np.random.default_rng(0)
    frames, labels = toy_sequence(rng, 3, (60, 80))
    params = toy_train_params((60, 80), n_trees=1, max_depth=2, samples_per_class=10)
    with pytest.raises(ValueError):
        train_forest(frames, labels[:2], params, rng)  # one label per frame
    with pytest.raises(ValueError):
        train_forest(frames + [np.zeros((10, 10), np.uint16)], labels + [None], params, rng)  # sizes differ
    with pytest.raises(ValueError):
        train_forest(frames, [(2, 40, 30)] * 3, params, rng, class_names=("background", "palm"))  # class 2 unnamed
    with pytest.raises(ValueError):
        train_forest_on_samples(SampleSet(np.zeros((1, 4, 4), np.float32), *(np.zeros(0, np.int32),) * 4, 2),
                                params.forest, params.features, rng)
