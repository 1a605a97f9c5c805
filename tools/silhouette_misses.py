#!/usr/bin/env python3
"""Where does the foreground lose the subject? Split the missed silhouette pixels of a bag.

Runs the foreground segmentation (:class:`~hmocap_ros.segmentation.BackgroundModel`, one per
camera, as ``hmocap eval mocap --silhouettes fg`` does: learning from the empty-room frames
before the subject appears) over a simulator bag and compares every mask with the bag's exact
``/ground_truth/cam_k/silhouette``. Per camera it prints the recall and precision, and splits
the subject pixels the mask misses by what the per-pixel test called them
(:func:`~hmocap_ros.segmentation.background_model.classify_and_update`):

- ``shadow``: darker or brighter than the background along its colour (eq. 4 of the module:
  a shadow or a highlight), i.e. the subject's colour is the background's at another
  brightness: an achromatic head or shirt in front of a grey wall;
- ``background``: within ``k_sigma`` of the background colour (camouflage proper);
- ``clean-up``: foreground in the raw test, removed by the opening or the blob filter.

It also says where along the silhouette's height (fifths, top to bottom) the ``shadow``
misses lie and their brightness ratios ``a_p / g`` (quantiles), the two figures that tell a
head lost against a wall (top fifth, ratio 0.5-0.95) from a shadowed foot.

::

    .venv/bin/python tools/silhouette_misses.py BAG.mcap [--frames N] [-p NAME=VALUE ...]

Stop 21 (``docs/tracking.md``, Limits): on the held-out run and on the tuning runner seed 25,
76-90 % of the missed subject pixels are ``shadow``, nearly all of them in the top fifth.
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hmocap_ros.io import topics  # noqa: E402
from hmocap_ros.io.bag_reader import BagReader  # noqa: E402
from hmocap_ros.io.conversions import image_to_numpy, image_to_rgb  # noqa: E402
from hmocap_ros.io.msg_factory import stamp_to_ns  # noqa: E402
from hmocap_ros.param_overrides import field_overrides  # noqa: E402
from hmocap_ros.rig import rig_from_msg  # noqa: E402
from hmocap_ros.segmentation import BackgroundModel, ForegroundParams  # noqa: E402

#: Frame-set stamps closer than this (ns) belong to one frame set (as in ``hmocap eval mocap``).
SLOP_NS = 10_000_000
#: Brightness-ratio quantiles printed for the ``shadow`` misses.
QUANTILES = (0.1, 0.25, 0.5, 0.75, 0.9)


@dataclasses.dataclass
class CameraMisses:
    """Pixel counts of one camera over the scored frames."""

    subject: int = 0            # ground-truth silhouette pixels
    detected: int = 0           # mask pixels
    hit: int = 0                # mask and silhouette
    shadow: int = 0             # missed, labelled shadow or highlight
    background: int = 0         # missed, within k_sigma of the background
    cleanup: int = 0            # missed, foreground before the clean-up
    shadow_by_fifth: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(5, np.int64))
    shadow_ratios: list = dataclasses.field(default_factory=list)

    @property
    def missed(self) -> int:
        return self.subject - self.hit

    @property
    def recall(self) -> float:
        return self.hit / self.subject if self.subject else float("nan")

    @property
    def precision(self) -> float:
        return self.hit / self.detected if self.detected else float("nan")


def _brightness_ratio(rgb: np.ndarray, mean: np.ndarray, gain: float) -> np.ndarray:
    """``a_p / g`` of eq. (2) of :mod:`hmocap_ros.segmentation.background_model`, per pixel."""
    img = rgb.astype(np.float32)
    return (img * mean).sum(-1) / np.maximum((mean * mean).sum(-1), 1.0) / np.float32(gain)


def split_misses(bag: str | Path, params: dict | None = None, max_frames: int | None = None,
                 min_subject_pixels: int = 200) -> dict[str, CameraMisses]:
    """Per camera name, the missed subject pixels of the bag's segmentation, split by label.

    params: ForegroundParams overrides (``learn_frames`` is set from the bag: the frames
    before the first ground-truth skeleton). Frames where a camera sees fewer than
    ``min_subject_pixels`` subject pixels are not scored for it. ``max_frames``: score at most
    this many frames with the subject.
    """
    with BagReader(bag) as reader:
        available = reader.topics()
        if topics.CAMERA_RIG not in available or topics.GT_SKELETON not in available:
            raise ValueError(f"{bag}: needs {topics.CAMERA_RIG} and {topics.GT_SKELETON} "
                             "(a simulator bag)")
        names = rig_from_msg(reader.first(topics.CAMERA_RIG)).names
        first = min(stamp_to_ns(item.msg.header.stamp)
                    for item in reader.messages([topics.GT_SKELETON]))
        images = [topics.camera_image(n) for n in names]
        truths = [topics.gt_silhouette(n) for n in names]
        missing = [t for t in images + truths if t not in available]
        if missing:
            raise ValueError(f"{bag}: missing topics {missing}")
        frame_sets = reader.frame_sets(images + truths, SLOP_NS, allow_partial=True,
                                       min_topics=1)
        models: list | None = None
        pending = []  # the empty-room frames, learnt once their number is known
        out = {n: CameraMisses() for n in names}
        scored = 0
        for stamp, msgs in frame_sets:
            if stamp < first:
                pending.append((stamp, msgs))
                continue
            if models is None:
                if not pending:
                    raise ValueError(f"{bag}: no empty-room frames before the subject appears")
                kw = dict(params or {})
                kw["learn_frames"] = int(np.clip(len(pending), 1, 100))  # as load_frames
                models = [BackgroundModel(ForegroundParams(**kw)) for _ in names]
                for s, m in pending:
                    for model, topic in zip(models, images):
                        if topic in m:
                            model.apply(image_to_rgb(m[topic]), s)
                pending = []
            for name, model, topic, gt_topic in zip(names, models, images, truths):
                if topic not in msgs:
                    continue
                rgb = image_to_rgb(msgs[topic])
                mask = model.apply(rgb, stamp) > 0
                if gt_topic not in msgs:
                    continue
                gt = image_to_numpy(msgs[gt_topic])
                gt = (gt[..., 0] if gt.ndim == 3 else gt) > 0
                if gt.sum() < min_subject_pixels:
                    continue
                miss = gt & ~mask
                shadow = miss & (model.shadow_mask > 0)
                raw = model.raw_mask > 0
                c = out[name]
                c.subject += int(gt.sum())
                c.detected += int(mask.sum())
                c.hit += int((gt & mask).sum())
                c.shadow += int(shadow.sum())
                c.background += int((miss & ~raw & ~shadow).sum())
                c.cleanup += int((miss & raw).sum())
                rows = np.flatnonzero(gt.any(axis=1))
                top, height = rows[0], rows[-1] - rows[0] + 1
                c.shadow_by_fifth += np.histogram((np.nonzero(shadow)[0] - top) / height,
                                                  bins=5, range=(0.0, 1.0))[0]
                if shadow.any():
                    ratio = _brightness_ratio(rgb, model.mean, model.gain)
                    c.shadow_ratios.append(ratio[shadow])
            scored += 1
            if max_frames is not None and scored >= max_frames:
                break
    return out


def _fractions(c: CameraMisses) -> str:
    if not c.missed:
        return "nothing missed"
    return (f"missed {c.missed}: shadow/highlight {c.shadow / c.missed:.2f}, background "
            f"{c.background / c.missed:.2f}, clean-up {c.cleanup / c.missed:.2f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bag")
    ap.add_argument("--frames", type=int, default=None, help="score at most this many frames")
    ap.add_argument("-p", dest="params", action="append", default=[], metavar="NAME=VALUE",
                    help="override a ForegroundParams field (repeatable)")
    ns = ap.parse_args(argv)
    try:
        params = field_overrides(ForegroundParams, ns.params, "ForegroundParams field")
    except ValueError as err:
        ap.error(f"-p: {err}")
    try:
        result = split_misses(ns.bag, params, ns.frames)
    except (ValueError, OSError) as err:
        print(f"silhouette_misses: {err}", file=sys.stderr)
        return 2
    ratios = []
    for name, c in result.items():
        fifths = c.shadow_by_fifth / max(c.shadow_by_fifth.sum(), 1)
        print(f"{name}: recall {c.recall:.3f}, precision {c.precision:.3f}; {_fractions(c)}; "
              f"shadow misses by fifth of the height (top first) "
              f"{' '.join(f'{f:.2f}' for f in fifths)}")
        ratios += c.shadow_ratios
    if ratios:
        q = np.quantile(np.concatenate(ratios), QUANTILES)
        print("brightness ratio of the shadow/highlight misses, quantiles "
              + ", ".join(f"{int(p * 100)}%: {v:.2f}" for p, v in zip(QUANTILES, q)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
