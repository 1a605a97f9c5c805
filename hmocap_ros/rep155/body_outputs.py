"""REP-155's per-body outputs as ROS4HRI's tools read them, built without rclpy.

Per tracked body ``<id>`` (topics relative, as the node publishes them; stamps the frame set's):

- ``humans/bodies/<id>/urdf`` (std_msgs/String, latched, as ROS4HRI's hri_fullbody publishes
  it): human_description's URDF (:mod:`hmocap_ros.body.human_description`) at the body's
  measured lengths, sent again when the body's shape changes; robot_state_publisher takes it
  as ``robot_description``;
- ``humans/bodies/<id>/joint_states`` (sensor_msgs/JointState): the URDF's joint angles
  (:data:`~hmocap_ros.body.human_description.URDF_JOINTS`, suffixed ``_<id>``) first, for
  robot_state_publisher, then the tracker's degrees of freedom by their names (``root_tx``, ...,
  what ``hmocap export`` and the tests rebuild the pose from; robot_state_publisher ignores
  names its URDF does not have): :meth:`Rep155Outputs.messages`;
- ``humans/bodies/<id>/skeleton2d`` (hri_msgs/Skeleton2D): the 18 OpenPose/COCO keypoints of
  the body in the camera that sees it best (the most joints inside its image, then the
  largest figure), normalised to [0, 1] by the image size, ``c`` the joint's confidence (0 for
  a keypoint outside the image and for the eyes and ears, which the tracker does not
  estimate: they sit at the head with confidence 0); frame_id the camera's optical frame;
- ``humans/bodies/<id>/roi`` (hri_msgs/NormalizedRegionOfInterest2D): the box of those
  keypoints in that camera, normalised, ``c`` their mean confidence;
- ``humans/bodies/<id>/position`` (geometry_msgs/PointStamped): the body frame's origin (the
  pelvis) in the room frame;
- ``humans/bodies/<id>/velocity`` (geometry_msgs/TwistStamped): its velocity in the room frame
  (finite differences smoothed over :data:`VELOCITY_TIME_CONSTANT_S`), from the body's second
  pose on.

:meth:`Rep155Outputs.messages` takes the tracker's messages of a frame set
(:class:`~hmocap_ros.tracking.tracker_messages.TrackerMessages`) and gives what the node
publishes: those, each body's joint_states led by the URDF's joints, the ``/tf`` frames of
the bodies prefixed with ``frame_prefix`` (two rooms on one DDS domain keep their bodies
apart; robot_state_publisher takes the same prefix as its ``frame_prefix``) and, with
``joint_frames`` false, only each body's ``body_<id>`` frame (robot_state_publisher adds the
URDF's frames; the tracker's joint frames share some of their names), then the outputs above.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from hmocap_ros.body.human_description import dimensions_from_joints, human_urdf, urdf_joint_names
from hmocap_ros.body.human_description import urdf_joint_positions as _angles
from hmocap_ros.io.msg_factory import make_header

__all__ = ["COCO_KEYPOINTS", "REP155_OUTPUT_TYPES", "VELOCITY_TIME_CONSTANT_S", "Rep155Outputs",
           "rep155_topics"]

#: Skeleton2D's keypoints in its order (hri_msgs/Skeleton2D constants) -> the tracking joint
#: placed there (None: the shoulders' middle for the neck; "head" with confidence 0 for the
#: eyes and ears)
COCO_KEYPOINTS = ("head", None, "r_shoulder", "r_elbow", "r_wrist", "l_shoulder", "l_elbow", "l_wrist",
                  "r_hip", "r_knee", "r_ankle", "l_hip", "l_knee", "l_ankle", "head", "head", "head", "head")
#: keypoints 14-17 (eyes, ears) are not estimated
_UNESTIMATED = frozenset(range(14, 18))
#: The topics (under ``humans/bodies/<id>/``) and their types.
REP155_OUTPUT_TYPES = {"urdf": "std_msgs/msg/String", "skeleton2d": "hri_msgs/msg/Skeleton2D",
                       "roi": "hri_msgs/msg/NormalizedRegionOfInterest2D",
                       "position": "geometry_msgs/msg/PointStamped",
                       "velocity": "geometry_msgs/msg/TwistStamped"}
#: Time constant (s) of the velocity's exponential smoothing.
VELOCITY_TIME_CONSTANT_S = 0.2


def rep155_topics(body_id: str) -> dict[str, str]:
    """``humans/bodies/<id>/<name>`` -> type of each output of :class:`Rep155Outputs`."""
    return {f"humans/bodies/{body_id}/{name}": kind for name, kind in REP155_OUTPUT_TYPES.items()}


class Rep155Outputs:
    """Builds the REP-155 outputs of each frame set (module docstring).

    ids: the tracker's body ids; frame_id: the room frame; cameras: the rig's cameras;
    factory: a message factory (:mod:`hmocap_ros.io.msg_factory`); frame_prefix, joint_frames:
    the bodies' /tf frames (:meth:`messages`).
    """

    def __init__(self, ids: Sequence[str], frame_id: str, cameras: Sequence, factory,
                 frame_prefix: str = "", joint_frames: bool = True):
        self.ids = tuple(ids)
        self.frame_id = frame_id
        self.cameras = list(cameras)
        self.factory = factory
        self.frame_prefix = frame_prefix
        self.joint_frames = joint_frames
        self.last_shape: list = [None] * len(self.ids)
        self.motion: list = [None] * len(self.ids)  # (stamp_ns, position, velocity)

    def messages(self, stamp_ns: int, results: Sequence, heights: Sequence[float], built: Sequence) -> list:
        """What the node publishes for a frame set (module docstring): ``built`` the tracker's
        ``(topic, message)`` of it, ``results`` and ``heights`` as :meth:`frame_set` takes them."""
        joint_topics = {f"humans/bodies/{body}/joint_states": k for k, body in enumerate(self.ids)}
        out = []
        for topic, msg in built:
            k = joint_topics.get(topic)
            if k is not None and results[k].has_pose and results[k].transforms is not None:
                msg = self.joint_state(self.ids[k], stamp_ns, results[k], msg)
            elif topic.lstrip("/") == "tf":
                msg = self._frames(msg)
            out.append((topic, msg))
        return out + self.frame_set(stamp_ns, results, heights)

    def _frames(self, msg):
        """The tracker's TFMessage with the body frames prefixed, and only the bodies' root
        frames without ``joint_frames``."""
        roots = {f"body_{body}" for body in self.ids}
        kept = [t for t in msg.transforms if self.joint_frames or t.child_frame_id in roots]
        for t in kept:
            if t.header.frame_id != self.frame_id:
                t.header.frame_id = self.frame_prefix + t.header.frame_id
            t.child_frame_id = self.frame_prefix + t.child_frame_id
        msg.transforms = kept
        return msg

    def frame_set(self, stamp_ns: int, results: Sequence, heights: Sequence[float]) -> list:
        """``(topic, message)`` of every body with a pose; ``heights``: each slot's standing
        height (m) at its estimated shape."""
        out = []
        for k, result in enumerate(results):
            if not result.has_pose:
                self.motion[k] = None
                continue
            body = self.ids[k]
            names = list(result.joint_names)
            joints = np.asarray(result.joints, dtype=np.float64)
            if result.shape is not None and result.shape is not self.last_shape[k]:
                self.last_shape[k] = result.shape
                dims = dimensions_from_joints(names, joints, float(heights[k]))
                out.append((f"humans/bodies/{body}/urdf",
                            self.factory.make("std_msgs/msg/String", data=human_urdf(body, dims))))
            pelvis = joints[names.index("pelvis")]
            out += self._motion(k, stamp_ns, pelvis)
            out += self._image_outputs(body, stamp_ns, names, joints, result.confidence)
        return out

    def joint_state(self, body_id: str, stamp_ns: int, result, tracker_state=None):
        """The joint_states of a pose (sensor_msgs/JointState): the URDF's joints of
        :func:`~hmocap_ros.body.human_description.urdf_joint_positions` (suffixed with the id),
        then the names and positions of ``tracker_state`` (the tracker's JointState) if given.
        ``result``: the slot's TrackResult (joint names, positions, transforms)."""
        from hmocap_ros.io.joint_states import make_joint_state
        from hmocap_ros.tracking.body_frames import REP155_AXES

        names = list(result.joint_names)
        rotations = np.asarray(result.transforms)[:, :3, :3] @ REP155_AXES
        angles = _angles(names, result.joints, rotations[names.index("pelvis")], rotations[names.index("head")])
        joint_names = urdf_joint_names(body_id)
        if tracker_state is not None:
            joint_names += [str(n) for n in tracker_state.name]
            angles = np.concatenate([angles, np.asarray(tracker_state.position, np.float64)])
        return make_joint_state(joint_names, angles, stamp_ns, self.frame_id, factory=self.factory)

    def _motion(self, k: int, stamp_ns: int, position: np.ndarray) -> list:
        f = self.factory
        body = self.ids[k]
        header = make_header(f, stamp_ns, self.frame_id)
        out = [(f"humans/bodies/{body}/position", f.make(
            "geometry_msgs/msg/PointStamped", header=header,
            point=f.make("geometry_msgs/msg/Point", x=float(position[0]), y=float(position[1]),
                         z=float(position[2]))))]
        previous = self.motion[k]
        velocity = None
        if previous is not None and stamp_ns > previous[0]:
            dt = (stamp_ns - previous[0]) * 1e-9
            raw = (position - previous[1]) / dt
            gain = 1.0 - np.exp(-dt / VELOCITY_TIME_CONSTANT_S)
            velocity = raw if previous[2] is None else previous[2] + gain * (raw - previous[2])
            out.append((f"humans/bodies/{body}/velocity", f.make(
                "geometry_msgs/msg/TwistStamped", header=make_header(f, stamp_ns, self.frame_id),
                twist=f.make("geometry_msgs/msg/Twist",
                             linear=f.make("geometry_msgs/msg/Vector3", x=float(velocity[0]),
                                           y=float(velocity[1]), z=float(velocity[2])),
                             angular=f.make("geometry_msgs/msg/Vector3")))))
        self.motion[k] = (stamp_ns, position.copy(), velocity)
        return out

    def _image_outputs(self, body: str, stamp_ns: int, names: list, joints: np.ndarray, confidence) -> list:
        """skeleton2d and roi in the camera that sees the body best (none when no camera does)."""
        from hmocap_ros.geometry import project_points

        if not self.cameras:
            return []
        at = {n: k for k, n in enumerate(names)}
        points = np.array([(joints[at["l_shoulder"]] + joints[at["r_shoulder"]]) / 2 if name is None
                           else joints[at[name]] for name in COCO_KEYPOINTS])
        joint_conf = np.ones(len(names)) if confidence is None or len(confidence) != len(names) \
            else np.clip(np.asarray(confidence, np.float64), 0.0, 1.0)
        conf = np.array([(joint_conf[at["l_shoulder"]] + joint_conf[at["r_shoulder"]]) / 2 if name is None
                         else joint_conf[at[name]] for name in COCO_KEYPOINTS])
        conf[list(_UNESTIMATED)] = 0.0
        projection = project_points(self.cameras, points)
        sizes = np.array([[c.width, c.height] for c in self.cameras], np.float64)
        normalised = projection.pixels / sizes[:, None, :]
        inside = projection.visible
        area = np.array([np.prod(np.ptp(xy[seen], axis=0)) if seen.any() else 0.0
                         for xy, seen in zip(normalised, inside)])
        best = int(np.lexsort((area, inside.sum(axis=1)))[-1])
        if not inside[best].any():
            return []
        f = self.factory
        header = make_header(f, stamp_ns, self.cameras[best].frame_id)
        xy = np.clip(normalised[best], 0.0, 1.0)
        c = np.where(inside[best], conf, 0.0)
        keypoints = [f.make("hri_msgs/msg/NormalizedPointOfInterest2D", x=float(x), y=float(y), c=float(v))
                     for (x, y), v in zip(xy, c)]
        seen = xy[inside[best]]
        lo, hi = seen.min(axis=0), seen.max(axis=0)
        estimated = inside[best] & (conf > 0)
        roi = f.make("hri_msgs/msg/NormalizedRegionOfInterest2D", header=make_header(f, stamp_ns,
                                                                                    self.cameras[best].frame_id),
                     xmin=float(lo[0]), ymin=float(lo[1]), xmax=float(hi[0]), ymax=float(hi[1]),
                     c=float(conf[estimated].mean()) if estimated.any() else 0.0)
        return [(f"humans/bodies/{body}/skeleton2d", f.make("hri_msgs/msg/Skeleton2D", header=header,
                                                            skeleton=keypoints)),
                (f"humans/bodies/{body}/roi", roi)]
