"""Ground truth of the gesture bag: the label of a frame (class, reference pixel, surface
point, visibility), its ``/ground_truth/gestures`` message and its record in the labels JSON;
on a near-miss frame, where the hand that is almost a gesture is (:func:`near_miss_truth`, the
``/ground_truth/near_misses`` message): training draws its hard background samples there.

The reference point (:func:`hmocap_sim.gesture_set.reference_point`) is projected to get
the pixel (u, v); the 3D position is the clean z-buffer depth at that pixel, back-projected,
when the surface seen there belongs to the gesture's body parts and lies within
:data:`SURFACE_TOLERANCE_M` of the reference point; otherwise the label keeps its class and
pixel and is marked not visible.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hmocap_ros.io.msg_factory import make_header
from hmocap_sim import gesture_set as gs
from hmocap_sim.depth_scene import Layout, pixel_to_optical
from hmocap_sim.gesture_takes import Actor, FrameState

SURFACE_TOLERANCE_M = 0.12  # the surface at (u, v) must be this close to the reference point


@dataclass
class GroundTruth:
    """Label of one frame: class (0 = background), reference pixel, surface point in the
    optical frame (metres) and whether the reference point is visible there."""

    class_id: int = 0
    name: str = "background"
    u: float | None = None
    v: float | None = None
    position: list | None = None
    visible: bool = False


def ground_truth(model, actor: Actor, state: FrameState, layout: Layout, render,
                 face_range: tuple) -> GroundTruth:
    """Label of one frame: class, reference pixel, surface point and visibility."""
    if state.phase != "hold":
        return GroundTruth()
    cam = layout.camera
    kin = gs.kinematics(model, actor.subject, state.params)
    ref = gs.reference_point(model, kin, state.kind, state.side)[0]
    pix, depth = cam.project(ref)
    u, v = float(pix[0]), float(pix[1])
    gt = GroundTruth(gs.class_id(state.kind), state.kind, u, v)
    col, row = int(round(u)), int(round(v))
    if not (cam.in_image(pix) and depth > 0 and 0 <= col < cam.width and 0 <= row < cam.height):
        gt.position = pixel_to_optical(cam, u, v, float(depth)).tolist()
        return gt
    z = float(render.zbuf[row, col])
    fid = int(render.face_id[row, col])
    parts = set(gs.reference_parts(model, state.kind, state.side))
    on_person = face_range[0] <= fid < face_range[1]
    if on_person:
        tri = model.faces[fid - face_range[0]]
        on_person = bool(parts.intersection(model.vertex_part[tri].tolist()))
    gt.visible = bool(on_person and np.isfinite(z) and abs(z - depth) < SURFACE_TOLERANCE_M)
    gt.position = pixel_to_optical(cam, u, v, z if gt.visible else float(depth)).tolist()
    return gt


def near_miss_truth(model, actor: Actor, state: FrameState, layout: Layout) -> GroundTruth:
    """Where a near miss is: the reference point of the gesture it misses
    (:data:`~hmocap_sim.gesture_kinds.NEAR_MISSES`), projected; ``class_id`` is that gesture's,
    ``name`` the near-miss kind, ``visible`` whether the point projects into the image in front
    of the camera. A frame that is no near miss (or the transition into one) gets an empty
    :class:`GroundTruth`."""
    missed = gs.NEAR_MISSES.get(state.kind)
    if missed is None or not state.side or state.phase == "transition":
        return GroundTruth()
    cam = layout.camera
    kin = gs.kinematics(model, actor.subject, state.params)
    ref = gs.reference_point(model, kin, missed, state.side)[0]
    pix, depth = cam.project(ref)
    u, v = float(pix[0]), float(pix[1])
    inside = bool(cam.in_image(pix) and depth > 0)
    return GroundTruth(gs.class_id(missed), state.kind, u, v,
                       pixel_to_optical(cam, u, v, float(depth)).tolist(), inside)


def gesture_array(factory, stamp_ns: int, frame_id: str, gt: GroundTruth):
    """The /ground_truth/gestures message of one frame."""
    gestures = []
    if gt.class_id:
        x, y, z = gt.position
        gestures.append(factory.make(
            "hmocap_interfaces/msg/Gesture", name=gt.name, class_id=gt.class_id, score=1.0, volume=1.0,
            u=gt.u, v=gt.v, position=factory.make("geometry_msgs/msg/Point", x=x, y=y, z=z),
            position_valid=gt.visible))
    return factory.make("hmocap_interfaces/msg/GestureArray",
                        header=make_header(factory, stamp_ns, frame_id), gestures=gestures)


def frame_record(model, index: int, stamp_ns: int, subject_id: int, layout_id: int,
                 state: FrameState, gt: GroundTruth, camera) -> dict:
    """The labels-JSON entry of one frame (``distance_m``: camera to pelvis)."""
    pelvis = state.params[model.skeleton.translation_dofs]
    return {
        "index": index, "stamp_ns": stamp_ns, "subject": subject_id, "layout": layout_id,
        "take": state.take, "phase": state.phase, "kind": state.kind, "class_id": gt.class_id,
        "name": gt.name, "side": state.side if gt.class_id else "",
        "u": None if gt.u is None else round(gt.u, 3),
        "v": None if gt.v is None else round(gt.v, 3),
        "position": None if gt.position is None else [round(c, 4) for c in gt.position],
        "visible": gt.visible,
        "distance_m": round(float(np.linalg.norm(camera.world_to_camera(pelvis))), 3)}
