"""Located hard negatives (thesis sec. 3.3.2, located by the annotation): a near-miss frame is
background labelled ``(0, u, v)`` with the point of the gesture it almost is; patch collection
draws negatives on that hand and mining looks there first, so the forest learns to refuse it."""

from __future__ import annotations

import dataclasses

import numpy as np
from fixtures.toy_depth import TOY_CLASSES, _disc, _rect, add_sensor_noise, toy_frame, toy_sequence, toy_train_params

from hmocap_ros.gestures import collect_samples, train_forest
from hmocap_ros.gestures.forest import frames_to_metres
from hmocap_ros.gestures.patches import mine_hard_negatives

SHAPE = (240, 320)


def near_miss_frame(rng: np.random.Generator):
    """A toy "palm" with two of its four fingers bent away: background, annotated with its palm centre."""
    f = 525.0 * SHAPE[1] / 640.0
    depth = float(rng.uniform(1.6, 2.6))
    s = f / depth
    u, v = rng.uniform(0.2 * s, SHAPE[1] - 0.2 * s), rng.uniform(0.25 * s, SHAPE[0] - 0.15 * s)
    z = np.full(SHAPE, np.float32(rng.uniform(3.5, 5.0)), np.float32)
    _rect(z, u, v + 0.25 * s, 0.38, 0.65, depth + 0.3, f)
    _disc(z, u, v + 0.10 * s - 0.35 * s, 0.1, depth + 0.3, f, aspect=1.25)
    _disc(z, u, v, 0.045, depth, f)
    for dx in (-0.03, 0.01):  # the other two fingers are missing
        _rect(z, u + dx * s, v - 0.075 * s, 0.016, 0.07, depth, f)
    return add_sensor_noise(rng, z), (0, int(round(u)), int(round(v)))


def _data(seed: int, n_gestures: int, n_near: int):
    rng = np.random.default_rng(seed)
    frames, labels = toy_sequence(rng, n_gestures, SHAPE)
    for _ in range(n_near):
        d, lab = near_miss_frame(rng)
        frames.append(d)
        labels.append(lab)
    return frames, labels


def test_near_miss_frames_give_negatives_on_the_hand_and_around_it():
    params = toy_train_params(SHAPE).patches
    rng = np.random.default_rng(1)
    d, lab = near_miss_frame(rng)
    metres = frames_to_metres([d], toy_train_params(SHAPE))
    located = collect_samples(metres, [lab], params, toy_train_params(SHAPE).features, np.random.default_rng(0), 3)
    plain = collect_samples(metres, [None], params, toy_train_params(SHAPE).features, np.random.default_rng(0), 3)
    assert np.all(located.label == 0) and len(plain) == params.n_negative
    d0 = float(metres[0, lab[2], lab[1]])
    box = params.box_half_size_px_m / d0
    ys, xs = np.mgrid[:SHAPE[0], :SHAPE[1]]
    hand = ((np.abs(xs - lab[1]) <= box) & (np.abs(ys - lab[2]) <= box)
            & (np.abs(metres[0] - d0) <= params.positive_depth_tolerance_m)).sum()
    assert len(located) == params.n_negative + min(params.n_near_miss, hand) + params.n_negative_near
    on_hand = (np.abs(located.x - lab[1]) <= box) & (np.abs(located.y - lab[2]) <= box)
    assert on_hand.sum() >= min(params.n_near_miss, hand) > 20
    assert np.all(np.abs(metres[0, located.y[on_hand], located.x[on_hand]] - d0) <= params.positive_depth_tolerance_m)
    near = params.near_half_size_px_m / d0
    around = (np.abs(located.x - lab[1]) <= near) & (np.abs(located.y - lab[2]) <= near) & ~on_hand
    assert around.sum() >= params.n_negative_near
    # without its point the frame is an ordinary negative frame: a few uniform draws land there
    hit = (np.abs(plain.x - lab[1]) <= box) & (np.abs(plain.y - lab[2]) <= box)
    assert hit.sum() < 0.1 * params.n_near_miss


def test_mining_draws_a_near_miss_frames_false_positives_at_the_near_miss_first():
    frames, labels = _data(2, 40, 0)
    params = toy_train_params(SHAPE, n_trees=3, max_depth=8, samples_per_class=400)
    forest = train_forest(frames, labels, params, np.random.default_rng(0), class_names=TOY_CLASSES)
    rng = np.random.default_rng(3)
    near = [near_miss_frame(rng) for _ in range(6)]
    metres = frames_to_metres([d for d, _ in near], params)
    mined = mine_hard_negatives(forest, metres, [lab for _, lab in near], params.patches,
                                np.random.default_rng(0), 8, 2)
    assert len(mined) > 0
    lab = np.array([lab for _, lab in near])[mined.frame]
    d = metres[mined.frame, lab[:, 2], lab[:, 1]]
    reach = 2.0 * params.patches.near_half_size_px_m / d
    at = (np.abs(mined.x - lab[:, 1]) <= reach) & (np.abs(mined.y - lab[:, 2]) <= reach)
    assert at.mean() > 0.9


def test_a_forest_taught_located_near_misses_refuses_them():
    """The same frames, near misses with and without their point: the located negatives lower the
    gesture's probability on held-out near misses and keep the gesture found on held-out palms."""
    frames, labels = _data(4, 90, 45)
    params = toy_train_params(SHAPE, n_trees=4, max_depth=12, samples_per_class=1500)
    params = dataclasses.replace(params, forest=dataclasses.replace(params.forest, mining_rounds=1))
    unlocated = [None if lab[0] == 0 and i >= 90 else lab for i, lab in enumerate(labels)]
    located = train_forest(frames, labels, params, np.random.default_rng(0), class_names=TOY_CLASSES)
    plain = train_forest(frames, unlocated, params, np.random.default_rng(0), class_names=TOY_CLASSES)

    rng = np.random.default_rng(9)
    test = [near_miss_frame(rng) for _ in range(12)]
    palms = [toy_frame(rng, SHAPE, 1) for _ in range(12)]

    def palm_votes(forest, frames_labels):
        metres = frames_to_metres([d for d, _ in frames_labels], params)
        out = []
        for k, (_, (_, u, v)) in enumerate(frames_labels):
            ys, xs = np.mgrid[v - 4:v + 5, u - 4:u + 5]
            ok = (ys >= 0) & (ys < SHAPE[0]) & (xs >= 0) & (xs < SHAPE[1])
            p = forest.predict_proba(metres, np.full(ok.sum(), k, np.int32), xs[ok].astype(np.int32),
                                     ys[ok].astype(np.int32))
            out.append(np.mean(p.argmax(1) == 1))
        return float(np.mean(out))

    assert palm_votes(located, test) < 0.5 * palm_votes(plain, test)
    assert palm_votes(located, palms) > 0.5


def test_located_negatives_are_a_stratum_of_every_bag():
    frames, labels = _data(6, 12, 6)
    params = toy_train_params(SHAPE, n_trees=2, max_depth=4, samples_per_class=200)

    def first_bag(share: float) -> int:
        p = dataclasses.replace(params, forest=dataclasses.replace(params.forest, located_share=share))
        forest = train_forest(frames, labels, p, np.random.default_rng(0), class_names=TOY_CLASSES)
        return forest.meta["training"]["trees"][0]["bag_size"]

    assert first_bag(1.0) == 4 * 200  # background, palm, tee and the located near misses
    assert first_bag(0.5) == 3 * 200 + 100
    assert first_bag(0.0) == 3 * 200  # drawn as any background sample
