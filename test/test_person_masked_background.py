"""Foreground without an empty room (``learn_from: person_masks``): each pixel learnt where the
person is not, the network's person mask standing in where it is not learnt yet.

A scripted mask source stands in for the network on synthetic scenes (what is learnt, when, and
what is not); the shipped demo bag, started at its first frame with the subject, checks the
whole model with the landmark network against the exact silhouettes.
"""
from pathlib import Path

import numpy as np
import pytest

from hmocap_ros.io import topics
from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.io.conversions import image_to_numpy, image_to_rgb
from hmocap_ros.io.rig_messages import rig_from_msg
from hmocap_ros.segmentation import ForegroundParams, PersonMaskedBackground, background_models, mask_scores

DEMO_BAG = Path(__file__).resolve().parents[1] / "hmocap_ros" / "data" / "demo" / "mocap_4cam.mcap"
H, W = 60, 80


class _ScriptedMasks:
    """Stands in for PersonMasks: returns the mask the test sets (or None: nobody)."""

    def __init__(self):
        self.mask = None
        self.calls = 0

    def reset(self, key=None):
        pass

    def probability(self, key, image):
        self.calls += 1
        return None if self.mask is None else self.mask.astype(np.float32)


def _room(rng) -> np.ndarray:
    base = np.zeros((H, W, 3), np.float32)
    base[:] = (90, 110, 130)
    base[:, : W // 2] = (150, 120, 90)  # two walls of different colour
    return base + rng.normal(0, 6, (H, W, 1))  # texture


def _frame(room, rng, boxes) -> np.ndarray:
    image = room + rng.normal(0, 2, room.shape)
    for (y0, y1, x0, x1), colour in boxes:
        image[y0:y1, x0:x1] = colour
    return np.clip(image, 0, 255).astype(np.uint8)


def _box_mask(y0, y1, x0, x1) -> np.ndarray:
    mask = np.zeros((H, W), bool)
    mask[y0:y1, x0:x1] = True
    return mask


def _params(**kw) -> ForegroundParams:
    return ForegroundParams(learn_from="person_masks", learn_frames=5, min_blob_area=4,
                            opening_size=0, closing_size=0, person_margin=0.05, **kw)


def test_a_person_there_from_the_first_frame_is_foreground_and_its_place_is_learnt_after():
    rng = np.random.default_rng(3)
    room = _room(rng)
    masks = _ScriptedMasks()
    model = PersonMaskedBackground(_params(), masks, "cam")
    person_a = (10, 50, 10, 22)
    person_b = (10, 50, 50, 62)
    for i in range(12):  # standing still at A: the network's mask is the foreground
        masks.mask = _box_mask(*person_a)
        out = model.apply(_frame(room, rng, [(person_a, (40, 200, 40))]), i)
        assert mask_scores(out, masks.mask).f1 > 0.95, i
    assert model.is_learning and 0.6 < model.learnt_fraction < 0.95
    for i in range(12, 24):  # at B: A's pixels become steady and free, and are learnt
        masks.mask = _box_mask(*person_b)
        out = model.apply(_frame(room, rng, [(person_b, (40, 200, 40))]), i)
    assert mask_scores(out, masks.mask).f1 > 0.95
    y0, y1, x0, x1 = person_a
    assert model._learnt[y0:y1, x0:x1].all()  # A learnt while the person stands at B
    np.testing.assert_allclose(model.mean[y0:y1, x0:x1], room[y0:y1, x0:x1], atol=6)
    # now background subtraction answers at A: a box the network does not mask is found there
    masks.mask = _box_mask(*person_b)
    stranger = (20, 40, 12, 20)
    out = model.apply(_frame(room, rng, [(person_b, (40, 200, 40)), (stranger, (220, 30, 30))]), 24)
    assert out[20:40, 12:20].mean() > 200


def test_something_moving_that_the_network_does_not_mask_is_never_learnt():
    rng = np.random.default_rng(4)
    room = _room(rng)
    masks = _ScriptedMasks()  # nobody, as far as the network can tell
    model = PersonMaskedBackground(_params(), masks, "cam")
    for i in range(30):  # a ball rolling to and fro over columns 30..56
        x = 30 + int(10 + 10 * np.sin(i))
        out = model.apply(_frame(room, rng, [((25, 35, x, x + 6), (250, 250, 40))]), i)
    # every pixel learnt holds the room, none the ball: a run that the ball broke started over
    learnt = model._learnt
    assert learnt.mean() > 0.95
    assert np.abs(model.mean[learnt] - room[learnt]).max() < 15
    assert out[25:35, x:x + 6].mean() > 200  # and the ball is foreground where it is now
    # the empty room learnt in learn_frames frames; the network stops once all is learnt
    masks2 = _ScriptedMasks()
    empty = PersonMaskedBackground(_params(), masks2, "cam")
    for i in range(8):
        empty.apply(_frame(room, rng, []), i)
    assert not empty.is_learning and masks2.calls == 5


def test_frames_of_another_size_or_older_stamps_are_refused():
    model = PersonMaskedBackground(_params(), _ScriptedMasks(), "cam")
    model.apply(np.zeros((H, W, 3), np.uint8), 10)
    with pytest.raises(ValueError, match="background model is"):
        model.apply(np.zeros((H + 1, W, 3), np.uint8), 11)
    with pytest.raises(ValueError, match="older"):
        model.apply(np.zeros((H, W, 3), np.uint8), 5)
    model.relearn()
    assert model.shape is None
    model.apply(np.zeros((H + 1, W, 3), np.uint8), 5)


def _demo_sets():
    with BagReader(DEMO_BAG) as reader:
        rig = rig_from_msg(reader.first(topics.CAMERA_RIG))
        wanted = [topics.camera_image(n) for n in rig.names] + [topics.gt_silhouette(n) for n in rig.names]
        return rig.names, list(reader.frame_sets(wanted, 0))


def _f1(models, names, sets) -> list[float]:
    scores = []
    for stamp, msgs in sets:
        row = []
        for model, name in zip(models, names):
            mask = model.apply(image_to_rgb(msgs[topics.camera_image(name)]), stamp)
            truth = image_to_numpy(msgs[topics.gt_silhouette(name)])
            if truth.any():
                row.append(mask_scores(mask, truth).f1)
        scores.append(np.mean(row) if row else np.nan)
    return scores


def test_demo_bag_from_its_first_frame_with_the_subject():
    """The demo's 4 views at 160x120 from the frame where the subject appears: the person-mask
    model finds the silhouettes from the first frame (0.85-0.93 per frame here); the empty-room
    model, learning from those frames, learns the person into its background (0 while it
    learns, 0.58 at best after). From the empty room it gives the empty-room model's masks and
    stops running the network once the room is learnt."""
    names, sets = _demo_sets()
    occupied = sets[8:]  # the bag's first 8 frame sets are the empty room
    small = {"min_blob_area": 10}
    person = _f1(background_models(ForegroundParams(learn_from="person_masks", **small), names),
                 names, occupied)
    empty = _f1(background_models(ForegroundParams(learn_frames=8, **small), names), names, occupied)
    assert min(person) > 0.8 and np.mean(person) > 0.85
    assert max(empty) < 0.7 and np.mean(person) > np.mean(empty) + 0.4
    models = background_models(ForegroundParams(learn_from="person_masks", learn_frames=8, **small), names)
    from_empty = _f1(models, names, sets)
    reference = _f1(background_models(ForegroundParams(learn_frames=8, **small), names), names,
                    sets)
    # the same masks but for the odd pixel whose noise restarted its run (learnt a frame later)
    np.testing.assert_allclose(from_empty[8:], reference[8:], atol=0.005)
    assert all(m.network_runs <= 12 and not m.is_learning for m in models)
