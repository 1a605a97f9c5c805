"""Foreground segmentation (thesis sec. 2.4, after Xu et al. [128]) on synthetic sequences.

Every scene is generated here with known ground truth: a static textured background, Gaussian
sensor noise, a moving coloured disc as the foreground, and cast shadows, illumination changes
and moved objects as the nuisances the model must not report.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from hmocap_ros.segmentation import (
    BackgroundModel,
    ForegroundParams,
    background_model,
    compile_kernels,
    mask_cleanup,
    mask_scores,
)
from hmocap_ros.segmentation.mask_cleanup import (
    clean_mask,
    fill_small_holes,
    remove_small_blobs,
    structuring_element,
)

NOISE_SIGMA = 3.0
BLOB_RGB = (220, 40, 60)
FRAME_NS = 40_000_000  # 25 fps


def textured_background(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """Float32 (h, w, 3) room-like texture: smooth colour patches plus fine static grain."""
    coarse = rng.uniform(50, 200, (h // 16 + 2, w // 16 + 2, 3)).astype(np.float32)
    bg = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC)
    grain = cv2.GaussianBlur(rng.normal(0, 15, (h, w, 3)).astype(np.float32), (0, 0), 1.0)
    return np.clip(bg + grain, 30, 225)


def camera_frame(scene: np.ndarray, rng: np.random.Generator, noise: float = NOISE_SIGMA) -> np.ndarray:
    """What the camera delivers: the scene plus Gaussian sensor noise, as uint8."""
    noisy = scene + noise * rng.standard_normal(scene.shape, dtype=np.float32)
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)


def disc_mask(h: int, w: int, center: tuple[int, int], radius: int) -> np.ndarray:
    mask = np.zeros((h, w), np.uint8)
    cv2.circle(mask, center, radius, 255, -1)
    return mask


def moving_center(t: int, h: int, w: int) -> tuple[int, int]:
    """A disc path that crosses the image (a few pixels per frame)."""
    return (int(w * (0.2 + 0.6 * (0.5 + 0.5 * np.sin(0.08 * t)))),
            int(h * (0.5 + 0.2 * np.cos(0.11 * t))))


def with_blob(scene: np.ndarray, truth: np.ndarray) -> np.ndarray:
    out = scene.copy()
    out[truth > 0] = BLOB_RGB
    return out


def learned_model(rng, bg, params=None, t0=0) -> BackgroundModel:
    model = BackgroundModel(params or ForegroundParams(learn_frames=15))
    for i in range(model.params.learn_frames):
        mask = model.apply(camera_frame(bg, rng), t0 + i * FRAME_NS)
        assert not mask.any(), "no foreground while learning"
    assert not model.is_learning
    return model


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


@pytest.fixture
def room(rng):
    return textured_background(rng, 240, 320)


def test_moving_blob_f1_after_learning(rng, room):
    h, w = room.shape[:2]
    model = BackgroundModel(ForegroundParams(learn_frames=15))
    assert model.is_learning
    for i in range(15):
        assert model.frames_learned == i
        assert not model.apply(camera_frame(room, rng), i * FRAME_NS).any()
    masks, truths = [], []
    for i in range(15, 75):
        truth = disc_mask(h, w, moving_center(i, h, w), 30)
        mask = model.apply(camera_frame(with_blob(room, truth), rng), i * FRAME_NS)
        assert mask.dtype == np.uint8 and mask.shape == (h, w)
        assert set(np.unique(mask)) <= {0, 255}
        masks.append(mask)
        truths.append(truth)
    scores = mask_scores(np.stack(masks), np.stack(truths))
    assert scores.f1.min() > 0.95, scores.f1.min()
    assert scores.f1.mean() > 0.98, scores.f1.mean()
    assert model.last_stamp_ns == 74 * FRAME_NS


def _shadow_scene(room, rng, suppression: bool):
    h, w = room.shape[:2]
    model = learned_model(rng, room, ForegroundParams(learn_frames=15, shadow_suppression=suppression))
    truth = disc_mask(h, w, (120, 100), 30)
    shadow = np.zeros((h, w), np.uint8)  # cast by the disc onto the floor, touching it
    cv2.ellipse(shadow, (175, 150), (90, 35), 20, 0, 360, 255, -1)
    shadow[truth > 0] = 0
    scene = room.copy()
    scene[shadow > 0] *= 0.6  # 40 % darker
    scene = with_blob(scene, truth)
    for i in range(3):
        mask = model.apply(camera_frame(scene, rng), (20 + i) * FRAME_NS)
    return model, mask, truth, shadow


def test_cast_shadow_is_not_foreground(rng, room):
    model, mask, truth, shadow = _shadow_scene(room, rng, suppression=True)
    in_shadow = shadow > 0
    assert np.count_nonzero(mask[in_shadow]) / np.count_nonzero(in_shadow) < 0.01
    assert np.count_nonzero(model.shadow_mask[in_shadow]) / np.count_nonzero(in_shadow) > 0.95
    assert mask_scores(mask, truth).f1 > 0.95


def test_without_shadow_suppression_the_shadow_is_foreground(rng, room):
    # The control for the test above: it is the shadow test that keeps the shadow out.
    model, mask, truth, shadow = _shadow_scene(room, rng, suppression=False)
    in_shadow = shadow > 0
    assert np.count_nonzero(mask[in_shadow]) / np.count_nonzero(in_shadow) > 0.9
    assert not model.shadow_mask.any()


def naive_difference_f1(learning: list, frames: list, truths: list) -> float:
    """Mean F1 of the best-thresholded difference against the mean of the learning frames
    (foreground where a channel differs by more than the threshold): a segmentation with no
    noise model, no shadows and no illumination."""
    reference = np.mean(np.stack(learning).astype(np.float32), axis=0)
    diff = np.stack([np.abs(f.astype(np.float32) - reference).max(axis=-1) for f in frames])
    truth = np.stack(truths)
    return max(float(mask_scores((diff > t).astype(np.uint8), truth).f1.mean())
               for t in (10, 15, 20, 30, 45, 60, 80))


def test_foreground_beats_naive_differencing_with_shadows_and_light_changes(rng, room):
    """A disc crossing the room with a cast shadow beside it, the lights dimmed by 12 %
    half-way: the model's F1 against differencing with the first frames (today 1.00 against
    0.86)."""
    h, w = room.shape[:2]
    model = BackgroundModel(ForegroundParams(learn_frames=15))
    learning = [camera_frame(room, rng) for _ in range(15)]
    for i, frame in enumerate(learning):
        model.apply(frame, i * FRAME_NS)
    frames, masks, truths = [], [], []
    for i in range(15, 45):
        centre = moving_center(i, h, w)
        truth = disc_mask(h, w, centre, 30)
        shadow = np.zeros((h, w), np.uint8)
        cv2.ellipse(shadow, (centre[0] + 50, centre[1] + 45), (70, 25), 20, 0, 360, 255, -1)
        shadow[truth > 0] = 0
        scene = room * (0.88 if i >= 30 else 1.0)
        scene[shadow > 0] *= 0.6
        frame = camera_frame(with_blob(scene, truth), rng)
        frames.append(frame)
        masks.append(model.apply(frame, i * FRAME_NS))
        truths.append(truth)
    f1 = float(mask_scores(np.stack(masks), np.stack(truths)).f1.mean())
    naive = naive_difference_f1(learning, frames, truths)
    assert f1 > 0.97 and f1 > naive + 0.08, (f1, naive)


@pytest.mark.parametrize("gain", [1.15, 0.85])
def test_global_illumination_change_is_not_foreground(rng, room, gain):
    h, w = room.shape[:2]
    model = learned_model(rng, room)
    for i in range(15, 20):
        truth = disc_mask(h, w, moving_center(i, h, w), 30)
        model.apply(camera_frame(with_blob(room, truth), rng), i * FRAME_NS)
    for i in range(20, 25):  # the lights change suddenly and stay so
        truth = disc_mask(h, w, moving_center(i, h, w), 30)
        mask = model.apply(camera_frame(with_blob(room * gain, truth), rng), i * FRAME_NS)
        scores = mask_scores(mask, truth)
        assert scores.false_positives / mask.size < 0.005
        assert scores.f1 > 0.95, scores.f1
        assert model.gain == pytest.approx(gain, abs=0.02)


@pytest.mark.parametrize("highlight, window_is_foreground", [(1.0, True), (1.15, False)])
def test_unevenly_changing_light_is_a_highlight_not_foreground(rng, room, highlight, window_is_foreground):
    # The lamp dims the room by 12 % but the window, lit by daylight, keeps its brightness: against
    # the global gain the window is 1.14 times brighter, along its own colour (a highlight).
    h, w = room.shape[:2]
    model = learned_model(rng, room, ForegroundParams(learn_frames=15, highlight_max_brightness=highlight))
    window = np.zeros((h, w), bool)
    window[20:80, 30:110] = True
    scene = room * 0.88
    scene[window] = room[window]
    truth = disc_mask(h, w, (220, 150), 30)
    for i in range(3):
        mask = model.apply(camera_frame(with_blob(scene, truth), rng), (20 + i) * FRAME_NS)
    assert model.gain == pytest.approx(0.88, abs=0.02)
    assert (np.count_nonzero(mask[window]) / np.count_nonzero(window) > 0.9) == window_is_foreground
    assert mask_scores(mask, truth).recall > 0.98  # the red disc is no highlight of the background


def test_brightening_floods_the_mask_without_compensation(rng, room):
    # (highlights off: a uniform 15 % brightening is also within the highlight range)
    model = learned_model(rng, room, ForegroundParams(learn_frames=15, illumination_compensation=False,
                                                      highlight_max_brightness=1.0))
    mask = model.apply(camera_frame(room * 1.15, rng), 20 * FRAME_NS)
    assert np.count_nonzero(mask) / mask.size > 0.5
    assert model.gain == 1.0


def test_background_adapts_slowly_only_where_there_is_no_foreground(rng):
    h, w = 120, 160
    bg = textured_background(rng, h, w)
    params = ForegroundParams(learn_frames=15, learning_rate=0.02, absorb_frames=0)
    model = learned_model(rng, bg, params)
    learned_mean = model.mean.copy()
    truth = disc_mask(h, w, (100, 50), 20)  # an object that stands still
    drifted = bg.copy()
    drifted[:, : w // 3] += 4.0  # a local lighting drift below the foreground threshold
    n = 60
    for i in range(n):
        mask = model.apply(camera_frame(with_blob(drifted, truth), rng), (15 + i) * FRAME_NS)
    moved = (model.mean - learned_mean)[:, : w // 3].mean()
    # The drift is tracked at the learning rate: 1 - (1 - rate)^n of it after n frames.
    assert moved == pytest.approx(4.0 * (1.0 - (1.0 - 0.02) ** n), abs=0.3)
    assert abs((model.mean - learned_mean)[100:, w // 2:].mean()) < 0.3
    # The first frame runs before the previous mask gates the update: the disc's rim may move.
    inside = cv2.erode(truth, np.ones((5, 5), np.uint8)) > 0
    assert np.abs(model.mean - learned_mean)[inside].max() < 1e-3
    assert mask_scores(mask, truth).f1 > 0.95


def test_persistent_change_is_absorbed_but_a_moving_object_is_not(rng):
    h, w = 120, 160
    bg = textured_background(rng, h, w)
    params = ForegroundParams(learn_frames=15, absorb_frames=30, absorb_rate=0.1)
    model = learned_model(rng, bg, params)
    changed = bg.copy()
    box = np.zeros((h, w), np.uint8)
    box[10:40, 110:150] = 255  # a chair moved into view, and left there
    changed[box > 0] = (40, 160, 200)
    box_fraction = []
    for i in range(15, 135):
        truth = disc_mask(h, w, moving_center(i, h, w), 15)
        truth[box > 0] = 0
        mask = model.apply(camera_frame(with_blob(changed, truth), rng), i * FRAME_NS)
        box_fraction.append(np.count_nonzero(mask[box > 0]) / np.count_nonzero(box))
        if i == 40:
            assert box_fraction[-1] > 0.95, "reported while it is new"
    assert box_fraction[-1] < 0.01, "absorbed after absorb_frames and the absorption itself"
    assert mask_scores(mask, truth).f1 > 0.95, "the moving disc is never absorbed"


def test_relearn_restarts_learning(rng, room):
    model = learned_model(rng, room)
    other = textured_background(rng, 240, 320)
    assert np.count_nonzero(model.apply(camera_frame(other, rng), 20 * FRAME_NS)) / other[..., 0].size > 0.5
    model.relearn()
    assert model.is_learning and model.frames_learned == 0 and model.shape is None
    for i in range(15):
        assert not model.apply(camera_frame(other, rng), (21 + i) * FRAME_NS).any()
    assert not model.is_learning
    mask = model.apply(camera_frame(other, rng), 40 * FRAME_NS)
    assert np.count_nonzero(mask) == 0
    # After relearn the size may change and the stamps may start over (a replayed bag).
    model.relearn()
    small = camera_frame(textured_background(rng, 60, 80), rng)
    model.apply(small, 0)
    assert model.shape == (60, 80) and model.last_stamp_ns == 0


def test_wrong_input_raises_clear_value_error(rng, room):
    model = learned_model(rng, room)
    good = camera_frame(room, rng)
    t = 20 * FRAME_NS
    bad_inputs = {
        "background model is 320x240": good[:200, :300],
        "must be uint8": good.astype(np.float32),
        "(H, W, 3) colour image": good[..., 0],
        "(H, W, 3) colour image, got shape (240, 320, 4)": np.dstack([good, good[..., :1]]),
        "numpy array": good.tolist(),
    }
    for message, frame in bad_inputs.items():
        with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
            model.apply(frame, t)
    with pytest.raises(ValueError, match="integer number of nanoseconds"):
        model.apply(good, 1.5)
    model.apply(good, t)
    with pytest.raises(ValueError, match="older than the previous"):
        model.apply(good, t - 1)
    # The model is unharmed by the rejected calls.
    assert model.last_stamp_ns == t
    assert not model.apply(good, t + FRAME_NS).any()


def test_grayscale_frame_rejected_before_learning():
    with pytest.raises(ValueError, match="colour image"):
        BackgroundModel().apply(np.zeros((48, 64), np.uint8), 0)


def test_non_contiguous_frame_is_accepted(rng):
    bg = textured_background(rng, 60, 80)
    model = BackgroundModel(ForegroundParams(learn_frames=5))
    for i in range(6):
        view = camera_frame(bg, rng)[..., ::-1]  # e.g. a BGR buffer seen as RGB
        assert not view.flags.c_contiguous
        mask = model.apply(view, i * FRAME_NS)
    assert not model.is_learning and not mask.any()


def test_same_input_gives_the_same_masks_bit_for_bit(room):
    def run():
        rng = np.random.default_rng(7)
        model = BackgroundModel(ForegroundParams(learn_frames=5))
        out = []
        for i in range(12):
            truth = disc_mask(240, 320, moving_center(i, 240, 320), 25)
            out.append(model.apply(camera_frame(with_blob(room, truth), rng), i))
        return np.stack(out), model.mean.copy()

    (m1, mean1), (m2, mean2) = run(), run()
    assert np.array_equal(m1, m2) and np.array_equal(mean1, mean2)


def test_compile_kernels_compiles_everything_segmenting_calls(rng, room):
    # A node compiles before it subscribes; a kernel left to compile on the first frames with a
    # person stalls it for seconds on a fresh checkout, and frames are dropped meanwhile.
    compile_kernels()
    kernels = [background_model.learn_step, background_model.estimate_gain,
               background_model.classify_and_update, mask_cleanup.component_areas,
               mask_cleanup._mark_border_labels, mask_cleanup._keep_labels, mask_cleanup._fill_labels]
    compiled = {k.__name__: len(k.signatures) for k in kernels}
    assert all(compiled.values()), compiled
    model = learned_model(rng, room, ForegroundParams(learn_frames=3, min_blob_area=50, max_hole_area=100))
    truth = disc_mask(240, 320, (160, 120), 30)
    scene = with_blob(room, truth)
    scene[118:123, 158:163] = room[118:123, 158:163]  # an enclosed hole
    scene[20:25, 20:25] = BLOB_RGB                     # a speck under min_blob_area
    mask = model.apply(camera_frame(scene, rng), 10 * FRAME_NS)
    assert mask[120, 160] == 255 and mask[22, 22] == 0
    assert {k.__name__: len(k.signatures) for k in kernels} == compiled


def test_params_are_validated_frozen_and_described():
    with pytest.raises(ValueError, match="k_sigma"):
        ForegroundParams(k_sigma=0.0)
    with pytest.raises(ValueError, match="shadow_min_brightness"):
        ForegroundParams(shadow_min_brightness=1.2)
    with pytest.raises(ValueError, match="learn_frames"):
        ForegroundParams(learn_frames=0)
    with pytest.raises(ValueError, match="learn_from must be one of empty_room, person_masks"):
        ForegroundParams(learn_from="guess")
    params = ForegroundParams()
    with pytest.raises(dataclasses.FrozenInstanceError):
        params.k_sigma = 2.0  # type: ignore[misc]
    for field in dataclasses.fields(ForegroundParams):
        assert len(field.metadata.get("description", "")) > 20, field.name
        assert type(field.default) in (int, float, bool, str), field.name


def test_clean_up_removes_specks_and_fills_enclosed_holes_only():
    mask = np.zeros((100, 100), np.uint8)
    cv2.circle(mask, (50, 50), 25, 255, -1)
    mask[48:52, 48:52] = 0  # small hole: filled
    mask[5:8, 5:8] = 255  # speck: removed
    ring = np.zeros_like(mask)
    cv2.circle(ring, (85, 85), 14, 255, 3)  # its inside (~490 pixels) is a big hole: kept
    mask |= ring
    out = clean_mask(mask, structuring_element(3), structuring_element(5),
                     min_blob_area=50, max_hole_area=100)
    assert out is not mask and mask[50, 50] == 0
    assert out[50, 50] == 255 and out[6, 6] == 0 and out[85, 85] == 0
    assert out[50, 30] == 255
    # The background outside the blobs touches the border: never a hole.
    border_ring = np.zeros((40, 40), np.uint8)
    border_ring[:, 10:13] = 255
    assert fill_small_holes(border_ring.copy(), 10_000).sum() == border_ring.sum()
    assert remove_small_blobs(border_ring.copy(), 121).sum() == 0
    assert remove_small_blobs(border_ring.copy(), 120).sum() == border_ring.sum()


def test_mask_scores_counts_and_conventions():
    truth = np.zeros((4, 5), np.uint8)
    truth[1:3, 1:4] = 255  # 6 pixels
    mask = np.zeros_like(truth)
    mask[1:3, 2:5] = 1  # 6 pixels, 4 of them true
    s = mask_scores(mask, truth)
    assert (s.true_positives, s.false_positives, s.false_negatives, s.true_negatives) == (4, 2, 2, 12)
    assert s.precision == pytest.approx(4 / 6) and s.recall == pytest.approx(4 / 6)
    assert s.f1 == pytest.approx(8 / 12) and s.iou == pytest.approx(4 / 8)
    # batches keep their leading axes; empty vs empty is perfect, empty vs something is zero
    batch = mask_scores(np.stack([mask, np.zeros_like(mask), np.zeros_like(mask)]),
                        np.stack([truth, np.zeros_like(truth), truth]))
    assert batch.f1.shape == (3,)
    assert batch.f1 == pytest.approx([8 / 12, 1.0, 0.0])
    assert batch.precision[2] == 0.0 and batch.recall[2] == 0.0
    # pixels outside `valid` are not counted
    valid = np.ones_like(truth, bool)
    valid[:, 4] = False
    sv = mask_scores(mask, truth, valid=valid)
    assert (sv.false_positives, sv.true_negatives) == (0, 10)
    with pytest.raises(ValueError, match="differ in image size"):
        mask_scores(mask, truth[:3])
    with pytest.raises(ValueError, match="do not broadcast"):
        mask_scores(np.stack([mask] * 2), np.stack([truth] * 3))
    # one truth against several cameras' masks
    assert mask_scores(np.stack([mask, truth]), truth).f1 == pytest.approx([8 / 12, 1.0])


def test_model_tracks_a_lasting_illumination_change(rng):
    bg = textured_background(rng, 120, 160)
    model = learned_model(rng, bg, ForegroundParams(learn_frames=15, learning_rate=0.1))
    gains = []
    for i in range(40):
        assert not model.apply(camera_frame(bg * 1.15, rng), (15 + i) * FRAME_NS).any()
        gains.append(model.gain)
    assert gains[0] == pytest.approx(1.15, abs=0.02)
    assert gains[-1] == pytest.approx(1.0, abs=0.02)  # the mean has caught up with the new light
