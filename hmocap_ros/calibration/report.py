"""The calibration report: per-camera figures as text, and a picture of the cameras in the
room from above and from the side (matplotlib, Agg backend)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["camera_rows", "report_text", "save_rig_picture"]


def camera_rows(names: list, solution, n_images: dict, n_detected: dict) -> list:
    """One dict per camera of the session: name, images, images with the board, board poses
    and corners used, RMS (px), position (m), or the reason it was left out."""
    bundle = solution.bundle
    rms = bundle.rms_per_camera()
    rows = []
    for c, name in enumerate(names):
        row = {"camera": name, "images": n_images.get(c, 0), "board_seen": n_detected.get(c, 0)}
        if c in solution.cameras:
            j = solution.cameras.index(c)
            mine = bundle.observations.camera == j
            row.update(poses=int(len(np.unique(bundle.observations.pose[mine]))),
                       corners=int(mine.sum()), rms_px=float(rms[j]),
                       position=(-solution.R[j].T @ solution.t[j]).tolist())
        else:
            row["left_out"] = solution.left_out.get(c, "not placed")
        rows.append(row)
    return rows


def report_text(rows: list, total_rms: float, room: str) -> str:
    lines = [f"room frame: {room}; overall reprojection RMS {total_rms:.3f} px",
             f"{'camera':12s} {'images':>6s} {'board':>6s} {'poses':>6s} {'corners':>8s} {'RMS px':>7s}  position (m)"]
    for r in rows:
        if "left_out" in r:
            lines.append(f"{r['camera']:12s} {r['images']:6d} {r['board_seen']:6d}  left out: {r['left_out']}")
        else:
            x, y, z = r["position"]
            lines.append(f"{r['camera']:12s} {r['images']:6d} {r['board_seen']:6d} {r['poses']:6d} "
                         f"{r['corners']:8d} {r['rms_px']:7.3f}  ({x:+.3f}, {y:+.3f}, {z:+.3f})")
    return "\n".join(lines) + "\n"


def save_rig_picture(path: Path, names: list, R: np.ndarray, t: np.ndarray,
                     board_centres: np.ndarray, title: str) -> None:
    """Cameras (centres, optical axes 0.5 m) and board centres in the room: from above (x, z)
    and from the side (x, y)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    centres = np.einsum("kji,kj->ki", R, -t)
    axes = R[:, 2, :]  # optical axis in the room
    fig, (top, side) = plt.subplots(1, 2, figsize=(11, 5))
    for ax, (i, j), label in ((top, (0, 2), "z (m)"), (side, (0, 1), "y (m), up")):
        ax.scatter(board_centres[:, i], board_centres[:, j], s=4, c="0.6", label="board")
        ax.scatter(centres[:, i], centres[:, j], c="C3", marker="^", s=50, label="camera")
        for c, a, name in zip(centres, axes, names):
            ax.plot([c[i], c[i] + 0.5 * a[i]], [c[j], c[j] + 0.5 * a[j]], "C3-")
            ax.annotate(name, (c[i], c[j]), textcoords="offset points", xytext=(4, 4), fontsize=8)
        ax.set_xlabel("x (m)")
        ax.set_ylabel(label)
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
    side.axhline(0.0, color="k", lw=0.8)
    top.set_title("from above")
    side.set_title("from the side")
    top.legend(loc="best", fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
