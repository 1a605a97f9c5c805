"""The messages of ``body_tracker`` for one tracked frame set, built without rclpy.

``body_tracker`` publishes what :meth:`TrackerMessages.frame_set` returns, and ``hmocap track``
writes the same messages into a bag, so a live run and an offline run of the tracker give the
same topics, types, stamps and contents. Messages are built through a message factory
(:mod:`hmocap_ros.io.msg_factory`: ``RclpyFactory`` in the node, ``RosbagsFactory`` for bags).

Topics (relative names, as the node publishes them; REP-155 for the ``humans/bodies`` ones;
every message stamped with the frame set's stamp, in the rig's room frame):

- ``humans/bodies/tracked`` (hri_msgs/IdsList, REP-155's type): the ids of the bodies with a
  pose, one message per frame set (empty: nobody);
- ``humans/bodies/<id>/joint_states`` (sensor_msgs/JointState) per body with a pose: the pose
  parameters by DoF name;
- ``skeleton`` (hmocap_interfaces/Skeleton) per body with a pose: 3D joints, parents,
  per-joint confidence (:mod:`hmocap_ros.tracking.body_frames`), fit cost;
- ``skeleton_markers`` (visualization_msgs/MarkerArray) per body with a pose: joints and bones,
  in the body's namespace (its id), kept by the viewer until replaced (no lifetime: poses may
  come seconds apart on a loaded machine); when a body that had a pose has none, one array
  with a ``DELETEALL`` marker goes first, so the lost body's skeleton disappears and the
  bodies still tracked are drawn again after it;
- ``humans/bodies/<id>/body_shape`` (hmocap_interfaces/BodyShape, latched) when the body's
  anthropometry is new, the first body's also on ``body_shape``;
- ``/tf`` (tf2_msgs/TFMessage): every tracked body's frames (``body_<id>``, ``<joint>_<id>``)
  in one message, with ``publish_tf``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from hmocap_ros.io.joint_states import make_joint_state
from hmocap_ros.io.msg_factory import make_header
from hmocap_ros.io.tf import TF_TOPIC, tf_message
from hmocap_ros.tracking.body_frames import body_transforms

__all__ = ["BODY_SHAPE_TOPIC", "MARKERS_TOPIC", "SKELETON_TOPIC", "TRACKED_TOPIC", "FrameSetMessages",
           "TrackerMessages", "latched_topics", "per_body_topic", "tracker_topics"]

#: REP-155's list of the bodies tracked now
TRACKED_TOPIC = "humans/bodies/tracked"
#: its type (ROS4HRI's, so REP-155 tools read it)
IDS_LIST_TYPE = "hri_msgs/msg/IdsList"
SKELETON_TOPIC = "skeleton"
MARKERS_TOPIC = "skeleton_markers"
#: the first body's shape, besides its per-body topic
BODY_SHAPE_TOPIC = "body_shape"
#: marker colours (r, g, b) of the bodies, in turn
BODY_COLOURS = ((1.0, 0.3, 0.0), (0.2, 0.9, 0.2), (1.0, 0.8, 0.1), (0.3, 0.5, 1.0))
#: visualization_msgs/Marker types and actions used here
SPHERE_LIST, LINE_LIST, ADD, DELETEALL = 7, 5, 0, 3


def per_body_topic(body_id: str, name: str) -> str:
    """REP-155's topic ``name`` of body ``body_id``: ``humans/bodies/<id>/<name>``."""
    return f"humans/bodies/{body_id}/{name}"


def tracker_topics(ids: Sequence[str], publish_tf: bool = True) -> dict[str, str]:
    """Every topic the tracker publishes for bodies ``ids`` -> its message type."""
    out = {TRACKED_TOPIC: IDS_LIST_TYPE,
           SKELETON_TOPIC: "hmocap_interfaces/msg/Skeleton",
           MARKERS_TOPIC: "visualization_msgs/msg/MarkerArray",
           BODY_SHAPE_TOPIC: "hmocap_interfaces/msg/BodyShape"}
    for body in ids:
        out[per_body_topic(body, "joint_states")] = "sensor_msgs/msg/JointState"
        out[per_body_topic(body, "body_shape")] = "hmocap_interfaces/msg/BodyShape"
    if publish_tf:
        out[TF_TOPIC] = "tf2_msgs/msg/TFMessage"
    return out


def latched_topics(ids: Sequence[str]) -> set[str]:
    """The topics of :func:`tracker_topics` that are latched (transient local)."""
    return {BODY_SHAPE_TOPIC, *(per_body_topic(body, "body_shape") for body in ids)}


@dataclass
class FrameSetMessages:
    """What one frame set gives: ``(topic, message)`` in publishing order, and the errors of
    bodies whose frames could not be built (a degenerate pose; the rest is published)."""

    messages: list = field(default_factory=list)
    errors: list = field(default_factory=list)


class TrackerMessages:
    """Builds the tracker's messages of each frame set (module docstring).

    model: the tracking body model (DoF names, parents); ids: the body ids of the tracker's
    slots; frame_id: the room frame; factory: a message factory. Keeps the last body shape
    sent per body: a shape goes out when it is new.
    """

    def __init__(self, model, ids: Sequence[str], frame_id: str, factory, publish_tf: bool = True):
        self.model = model
        self.ids = tuple(ids)
        self.frame_id = frame_id
        self.factory = factory
        self.publish_tf = publish_tf
        self.last_shape = [None] * len(self.ids)
        self.had_pose = [False] * len(self.ids)

    def frame_set(self, stamp_ns: int, results: Sequence, shape_models: Sequence) -> FrameSetMessages:
        """The messages of one frame set: ``results`` one per slot (TrackResult),
        ``shape_models`` the body model each slot's shape scales (its height)."""
        out = FrameSetMessages()
        posed = [bool(result.has_pose) for result in results]
        if any(had and not now for had, now in zip(self.had_pose, posed)):
            out.messages.append((MARKERS_TOPIC, self.delete_all(stamp_ns)))
        self.had_pose = posed
        for k, result in enumerate(results):
            if result.has_pose:
                out.messages += self.pose(k, stamp_ns, result, shape_models[k])
        tracked = [body for body, result in zip(self.ids, results) if result.has_pose]
        out.messages.append((TRACKED_TOPIC, self.factory.make(
            IDS_LIST_TYPE, header=self._header(stamp_ns), ids=tracked)))
        if self.publish_tf:
            tf, out.errors = self.transforms(stamp_ns, results)
            if tf is not None:
                out.messages.append((TF_TOPIC, tf))
        return out

    def _header(self, stamp_ns: int):
        return make_header(self.factory, stamp_ns, self.frame_id)

    def pose(self, k: int, stamp_ns: int, result, shape_model) -> list:
        """Joint states, skeleton, markers and (when new) body shape of slot ``k``."""
        f = self.factory
        body = self.ids[k]
        out = [(per_body_topic(body, "joint_states"),
                make_joint_state(self.model.skeleton.dof_names, result.params, stamp_ns, self.frame_id,
                                 factory=f))]
        confidence = result.confidence
        out.append((SKELETON_TOPIC, f.make(
            "hmocap_interfaces/msg/Skeleton", header=self._header(stamp_ns), body_id=body,
            joint_names=list(result.joint_names), positions=self._points(result.joints),
            parents=np.asarray(self.model.parents, np.int32),
            confidence=np.zeros(0, np.float32) if confidence is None else np.asarray(confidence, np.float32),
            fit_error=float(result.fit_cost))))
        out.append((MARKERS_TOPIC, self.markers(k, stamp_ns, result.joints)))
        if result.shape is not None and result.shape is not self.last_shape[k]:
            self.last_shape[k] = result.shape
            shape = result.shape
            msg = f.make("hmocap_interfaces/msg/BodyShape", header=self._header(stamp_ns), body_id=body,
                         entity_names=list(shape.entity_names),
                         bone_scale=np.ravel(shape.bone_scale).astype(np.float32),
                         radial_scale=np.ravel(shape.radial_scale).astype(np.float32),
                         global_scale=float(shape.global_scale), height=float(shape.height(shape_model)))
            out.append((per_body_topic(body, "body_shape"), msg))
            if k == 0:
                out.append((BODY_SHAPE_TOPIC, msg))
        return out

    def _points(self, joints: np.ndarray) -> list:
        return [self.factory.make("geometry_msgs/msg/Point", x=float(p[0]), y=float(p[1]), z=float(p[2]))
                for p in np.asarray(joints)]

    def markers(self, k: int, stamp_ns: int, joints: np.ndarray):
        """Spheres at the joints and lines along the bones of slot ``k``, one namespace per body."""
        f = self.factory
        body = self.ids[k]
        points = self._points(joints)
        # the identity pose (rclpy's default; a rosbags default quaternion is all zeros)
        pose = f.make("geometry_msgs/msg/Pose", orientation=f.make("geometry_msgs/msg/Quaternion", w=1.0))
        r, g, b = BODY_COLOURS[k % len(BODY_COLOURS)]
        spheres = f.make("visualization_msgs/msg/Marker", header=self._header(stamp_ns), ns=body, id=0,
                         type=SPHERE_LIST, action=ADD,
                         scale=f.make("geometry_msgs/msg/Vector3", x=0.06, y=0.06, z=0.06),
                         color=f.make("std_msgs/msg/ColorRGBA", r=r, g=g, b=b, a=1.0),
                         pose=pose, points=points)
        bone_points = []
        for child, parent in enumerate(self.model.parents):
            if parent >= 0:
                bone_points += [points[parent], points[child]]
        bones = f.make("visualization_msgs/msg/Marker", header=self._header(stamp_ns), ns=body, id=1,
                       type=LINE_LIST, action=ADD,
                       scale=f.make("geometry_msgs/msg/Vector3", x=0.02),
                       color=f.make("std_msgs/msg/ColorRGBA", r=0.0, g=0.8, b=1.0, a=1.0),
                       pose=pose, points=bone_points)
        return f.make("visualization_msgs/msg/MarkerArray", markers=[spheres, bones])

    def delete_all(self, stamp_ns: int):
        """A MarkerArray holding one ``DELETEALL`` marker: the viewer drops every skeleton."""
        f = self.factory
        pose = f.make("geometry_msgs/msg/Pose", orientation=f.make("geometry_msgs/msg/Quaternion", w=1.0))
        marker = f.make("visualization_msgs/msg/Marker", header=self._header(stamp_ns), action=DELETEALL,
                        pose=pose)
        return f.make("visualization_msgs/msg/MarkerArray", markers=[marker])

    def transforms(self, stamp_ns: int, results: Sequence):
        """Every tracked body's frames in one TFMessage (None when no body has frames), and
        the errors of the bodies left out."""
        transforms, errors = [], []
        for body, result in zip(self.ids, results):
            if result.transforms is None:
                continue
            try:
                transforms += body_transforms(result.joint_names, self.model.parents,
                                              result.transforms, body, self.frame_id)
            except ValueError as err:  # a degenerate pose must not stop the others
                errors.append(f"{body}: no frames on {TF_TOPIC}: {err}")
        return (tf_message(transforms, stamp_ns, self.factory) if transforms else None), errors
