"""Contact sheet of a gesture bag: a few depth frames per class, colour-mapped, with the
ground-truth point and the class name drawn, read back from the written bag."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from hmocap_ros.io import topics
from hmocap_sim import gesture_set as gs
from hmocap_sim.gesture_labels import GroundTruth

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
    """Read the chosen frames back from the bag and write the PNG: rows = the six classes (and
    the taught gestures the bag holds) then background, columns = frames
    (:func:`select_sheet_frames`)."""
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
    present = {r["class_id"] for r in records}
    extra = [gs.class_id(g) for g in gs.NEW_GESTURES if gs.class_id(g) in present]
    for cid in list(range(1, len(gs.GESTURE_CLASSES) + 1)) + extra + [0]:
        row = [tiles[i] for i in chosen.get(cid, [])]
        rows.append(np.hstack(row + [blank] * (columns - len(row))))
    sheet = np.vstack(rows)
    for x in range(1, columns):
        sheet[:, x * TILE[0]] = 255
    for y in range(1, len(rows)):
        sheet[y * TILE[1]] = 255
    cv2.imwrite(str(path), sheet, [cv2.IMWRITE_PNG_COMPRESSION, 9])
