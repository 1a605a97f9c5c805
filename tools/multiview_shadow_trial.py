#!/usr/bin/env python3
"""Trial (stop 21) of a multi-view shadow test for the foreground; not used by the nodes.

The per-pixel shadow test (eq. 4 of :mod:`hmocap_ros.segmentation.background_model`) takes an
achromatic head or shirt in front of a light grey wall for the wall's shadow
(``tools/silhouette_misses.py``). Colour cannot tell the two apart; geometry can: a shadow
lies on the floor or a wall, and the other cameras see no object in front of it. So, per
frame set:

1. segment every camera as the node does (:class:`~hmocap_ros.segmentation.BackgroundModel`);
2. carve the visual hull (:func:`~hmocap_ros.tracking.visual_hull.visual_hull`, every view
   required, at ``--scale`` of the image) from *foreground or shadow* in each view, inside
   the cameras' room box less ``--wall-margin`` at the walls and above ``--floor-lift``;
3. project its voxels into each view (``--dilate`` square) and call the shadow-labelled
   pixels there foreground, then clean the mask as the model does.

Prints precision, recall and F1 of the subject's silhouette (pooled over cameras and frames
with at least 200 subject pixels) against the bag's exact silhouettes, for the model alone
and with the test. Stop 21, tuning runner bags 25 and 28 (``docs/tracking.md``, Tuning):

    .venv/bin/python tools/multiview_shadow_trial.py /tmp/ev/tune_02_03_s25.mcap \\
        /tmp/ev/tune_02_03_s28.mcap        # F1 0.959 -> 0.967 (recall 0.940 -> 0.992)

It reaches into the model's clean-up settings (``_opening``, ``_closing``): a trial, to be
rebuilt in the package (the segmentation node holding the rig) if tracking gains from it.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hmocap_ros.io import topics  # noqa: E402
from hmocap_ros.io.bag_reader import BagReader  # noqa: E402
from hmocap_ros.io.conversions import image_to_numpy, image_to_rgb  # noqa: E402
from hmocap_ros.io.msg_factory import stamp_to_ns  # noqa: E402
from hmocap_ros.render.projection import project_batch  # noqa: E402
from hmocap_ros.rig import camera_arrays, rig_from_msg  # noqa: E402
from hmocap_ros.segmentation import BackgroundModel, ForegroundParams  # noqa: E402
from hmocap_ros.segmentation.mask_cleanup import clean_mask  # noqa: E402
from hmocap_ros.tracking.body_fitness import downsample_mask  # noqa: E402
from hmocap_ros.tracking.visual_hull import room_bounds, visual_hull  # noqa: E402


def hull_shadow_masks(models, masks, work, full, bounds, dilate):
    """Masks with the shadow pixels inside the projection of the (foreground | shadow) hull
    turned to foreground; ``masks`` unchanged when no hull is found."""
    both = np.stack([downsample_mask(((m | (bm.shadow_mask > 0)) * 255).astype(np.uint8),
                                     w.width, w.height)
                     for m, bm, w in zip(masks, models, work)])
    hull = visual_hull(both, *camera_arrays(work), bounds, min_views=len(models))
    if hull is None:
        return masks
    uv, _ = project_batch(hull.points[None].astype(np.float64), *full)
    out = []
    for c, (mask, bm) in enumerate(zip(masks, models)):
        h, w = mask.shape
        proj = np.zeros((h, w), np.uint8)
        p = np.round(uv[0, c]).astype(int)
        ok = (p[:, 0] >= 0) & (p[:, 0] < w) & (p[:, 1] >= 0) & (p[:, 1] < h)
        proj[p[ok, 1], p[ok, 0]] = 255
        proj = cv2.dilate(proj, np.ones((dilate, dilate), np.uint8))
        raw = bm.raw_mask.copy()
        raw[(bm.shadow_mask > 0) & (proj > 0)] = 255
        out.append(clean_mask(raw, bm._opening, bm._closing, bm.params.min_blob_area,
                              bm.params.max_hole_area) > 0)
    return out


def score(bag: str, ns) -> dict:
    """(tp, fp, fn) per variant ("model", "multi-view") over one bag."""
    with BagReader(bag) as reader:
        rig = rig_from_msg(reader.first(topics.CAMERA_RIG))
        first = min(stamp_to_ns(it.msg.header.stamp)
                    for it in reader.messages([topics.GT_SKELETON]))
        names = rig.names
        tops = [topics.camera_image(n) for n in names] + [topics.gt_silhouette(n) for n in names]
        sets = list(reader.frame_sets(tops, 10_000_000, allow_partial=True, min_topics=1))
    learn = int(np.clip(sum(1 for s, _ in sets if s < first), 1, 100))
    work = [c.scaled(ns.scale) for c in rig]
    full = camera_arrays(list(rig))
    lo, hi = room_bounds(list(rig), margin=ns.wall_margin)
    lo = lo.copy()
    lo[1] = ns.floor_lift
    out = {}
    for variant in ("model", "multi-view"):
        models = [BackgroundModel(ForegroundParams(learn_frames=learn)) for _ in names]
        counts = np.zeros(3, np.int64)
        for i, (stamp, msgs) in enumerate(sets):
            masks = [bm.apply(image_to_rgb(msgs[topics.camera_image(n)]), stamp) > 0
                     for bm, n in zip(models, names)]
            if i < learn:
                continue
            if variant == "multi-view":
                masks = hull_shadow_masks(models, masks, work, full, (lo, hi), ns.dilate)
            for mask, n in zip(masks, names):
                if topics.gt_silhouette(n) not in msgs:
                    continue
                gt = image_to_numpy(msgs[topics.gt_silhouette(n)])
                gt = (gt[..., 0] if gt.ndim == 3 else gt) > 0
                if gt.sum() < 200:
                    continue
                counts += [(mask & gt).sum(), (mask & ~gt).sum(), (~mask & gt).sum()]
        out[variant] = counts
    return out


def _line(label: str, counts) -> str:
    tp, fp, fn = (int(c) for c in counts)
    p, r = tp / max(tp + fp, 1), tp / max(tp + fn, 1)
    return f"{label}: precision {p:.3f} recall {r:.3f} F1 {2 * p * r / max(p + r, 1e-12):.3f}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bags", nargs="+", help="simulator bags with exact silhouettes")
    ap.add_argument("--floor-lift", type=float, default=0.5, help="hull starts this high (m)")
    ap.add_argument("--wall-margin", type=float, default=0.2, help="room box shrunk by (m)")
    ap.add_argument("--dilate", type=int, default=3, help="projected voxel square (pixels)")
    ap.add_argument("--scale", type=float, default=0.25, help="image scale of the hull")
    ns = ap.parse_args(argv)
    total: dict = {}
    for bag in ns.bags:
        result = score(bag, ns)
        for variant, counts in result.items():
            print(_line(f"{Path(bag).name} {variant}", counts), flush=True)
            total[variant] = total.get(variant, 0) + counts
    for variant, counts in total.items():
        print(_line(f"pooled {variant}", counts))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
