"""One body's recorded motion read from a bag into arrays: the input of every exporter.

A bag holds the motion in two kinds (:data:`MOTION_SOURCES`): what ``body_tracker`` publishes
(``skeleton``, latched ``body_shape`` of the first body, and per body (REP-155)
``humans/bodies/<id>/joint_states`` / ``body_shape``; under the namespace the recording was
made in, e.g. ``/room/skeleton``) and the simulator's ground truth (``/ground_truth/skeleton``,
``/ground_truth/joint_states``, ``/ground_truth/body_shape``; docs/simulator.md). Skeleton
messages carry a ``body_id``; joint states do not, so a body's joint states are read from its
per-body topic, and for the first body (the one on the plain ``body_shape`` topic, or the
first on the skeleton topic) without one, from a plain ``joint_states`` topic beside the
skeleton (a recording of another publisher of one body).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["MOTION_SOURCES", "BodyMotion", "ExportError", "MotionSource", "read_motion"]

SKELETON_TYPE = "hmocap_interfaces/msg/Skeleton"
JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"
BODY_SHAPE_TYPE = "hmocap_interfaces/msg/BodyShape"


class ExportError(ValueError):
    """The bag lacks what an export needs; the message names what it has instead."""


@dataclass(frozen=True)
class MotionSource:
    """Where a bag keeps one kind of motion: topic names relative to the recording's namespace.

    ``per_body``: the prefix of per-body topics (``{body_id}`` filled in), or "" when the
    source has only the plain ones. ``not_under``: namespaces that belong to another source.
    """

    name: str
    skeleton: str
    joint_states: str
    body_shape: str
    per_body: str = ""
    not_under: tuple = ()

    def skeleton_topic(self, types: dict[str, str], bag: Path) -> str:
        """The one skeleton topic of this source among ``types`` (topic -> message type) of ``bag``."""
        found = [t for t, msgtype in types.items()
                 if msgtype == SKELETON_TYPE and (t == f"/{self.skeleton}" or t.endswith(f"/{self.skeleton}"))
                 and not any(t[:-len(self.skeleton)].endswith(f"/{ns}/") for ns in self.not_under)]
        if not found:
            others = [k for k, src in MOTION_SOURCES.items() if src is not self
                      and any(t.endswith(f"/{src.skeleton}") for t in types)]
            hint = f"; try --source {others[0]}" if others else ""
            raise ExportError(f"{bag}: no {self.name} skeleton ({self.skeleton}, {SKELETON_TYPE}){hint} "
                              f"(the bag has {', '.join(sorted(types)) or 'no topics'})")
        if len(found) > 1:
            raise ExportError(f"{bag}: several {self.name} skeleton topics ({', '.join(sorted(found))}); "
                              "export a bag of one recording namespace")
        return found[0]

    def body_topic(self, types: dict, namespace: str, relative: str, msgtype: str, body_id: str,
                   first_body: bool) -> str | None:
        """The topic of ``relative`` (joint states or body shape, of type ``msgtype``) that
        carries ``body_id``, or None."""
        if self.per_body:
            own = namespace + self.per_body.format(body_id=body_id) + relative
            if types.get(own) == msgtype:
                return own
        plain = namespace + relative
        return plain if first_body and types.get(plain) == msgtype else None


#: The kinds of motion a bag can hold, by ``--source`` name.
MOTION_SOURCES = {
    "tracked": MotionSource("tracked", "skeleton", "joint_states", "body_shape",
                            per_body="humans/bodies/{body_id}/", not_under=("ground_truth",)),
    "truth": MotionSource("truth", "ground_truth/skeleton", "ground_truth/joint_states",
                          "ground_truth/body_shape"),
}


@dataclass(frozen=True, eq=False)
class BodyMotion:
    """One body's motion, frames in stamp order.

    Skeleton: ``stamps_ns`` (F,) int64, ``point_names`` (P,) and ``parents`` (P,) as the
    messages list them, ``points`` (F, P, 3) metres in the room frame (+Y up).
    Joint states: ``dof_stamps_ns`` (G,), ``dof_names`` (D,), ``dofs`` (G, D) metres/radians
    (G = 0 when the bag has none for this body). ``shapes``: ``(stamp_ns, BodyShape)`` of every
    body-shape message of this body, in stamp order. ``topics``: what was read, by role;
    ``bag_topics``: every topic of the bag.
    """

    bag: Path
    source: str
    body_id: str
    stamps_ns: np.ndarray
    point_names: tuple
    parents: np.ndarray
    points: np.ndarray
    dof_stamps_ns: np.ndarray
    dof_names: tuple
    dofs: np.ndarray
    shapes: tuple = ()
    topics: dict = field(default_factory=dict)
    bag_topics: tuple = ()

    @property
    def n_frames(self) -> int:
        return len(self.stamps_ns)

    def dofs_at_skeleton_frames(self) -> np.ndarray:
        """(F, D) joint-state values at the skeleton's stamps, NaN where none has that stamp."""
        out = np.full((self.n_frames, len(self.dof_names)), np.nan)
        if len(self.dof_stamps_ns):
            i = np.clip(np.searchsorted(self.dof_stamps_ns, self.stamps_ns), 0, len(self.dof_stamps_ns) - 1)
            hit = self.dof_stamps_ns[i] == self.stamps_ns
            out[hit] = self.dofs[i[hit]]
        return out


def _in_stamp_order(stamps: list, *arrays) -> tuple:
    """Sort by stamp and keep the first message of each stamp."""
    stamp_array = np.asarray(stamps, dtype=np.int64)
    order = np.argsort(stamp_array, kind="stable")
    keep = order[np.concatenate([[True], np.diff(stamp_array[order]) != 0])] if len(order) else order
    return (stamp_array[keep],) + tuple(np.asarray(a)[keep] for a in arrays)


def _read_skeletons(reader, topic: str, body_id: str | None) -> tuple:
    """(all body ids in order of appearance, the chosen id, stamps, points, names, parents) of
    the chosen body's skeleton messages (default: the first body)."""
    from hmocap_ros.io.msg_factory import stamp_to_ns

    ids: list = []
    stamps, points = [], []
    names = parents = None
    for item in reader.messages([topic]):
        msg = item.msg
        bid = str(msg.body_id)
        if bid not in ids:
            ids.append(bid)
        if bid != (body_id if body_id is not None else ids[0]):
            continue
        these = tuple(str(n) for n in msg.joint_names)
        if len(msg.positions) != len(these):
            raise ExportError(f"{reader.path}: a skeleton of {bid} on {topic} has {len(msg.positions)} "
                              f"positions for {len(these)} joint names")
        if names is None:
            names, parents = these, np.asarray(msg.parents, dtype=np.int64)
        elif these != names:
            raise ExportError(f"{reader.path}: the joints of {bid} on {topic} change at stamp "
                              f"{stamp_to_ns(msg.header.stamp)} ({len(names)} then {len(these)} names)")
        stamps.append(stamp_to_ns(msg.header.stamp))
        points.append([(p.x, p.y, p.z) for p in msg.positions])
    if not ids:
        raise ExportError(f"{reader.path}: {topic} holds no message")
    chosen = body_id if body_id is not None else ids[0]
    if chosen not in ids:
        raise ExportError(f"{reader.path}: no body {chosen!r} on {topic} (body ids: {', '.join(ids)})")
    return (ids, chosen, *_in_stamp_order(stamps, np.asarray(points, dtype=np.float64).reshape(len(stamps), -1, 3)),
            names, parents)


def _read_joint_states(reader, topic: str | None) -> tuple:
    """(stamps, DoF names, values) of a joint-state topic; names of the first message, the
    values of later messages reordered by name."""
    from hmocap_ros.io.conversion_errors import JointStateConversionError
    from hmocap_ros.io.joint_states import joint_state_to_dict

    if topic is None:
        return np.zeros(0, np.int64), (), np.zeros((0, 0))
    names, stamps, rows = None, [], []
    for item in reader.messages([topic]):
        try:
            js = joint_state_to_dict(item.msg)
        except JointStateConversionError as err:
            raise ExportError(f"{reader.path}: {topic}: {err}") from None
        if names is None:
            names = tuple(js["name"])
        if tuple(js["name"]) == names:
            rows.append(js["position"])
        else:
            where = {n: i for i, n in enumerate(js["name"])}
            missing = [n for n in names if n not in where]
            if missing:
                raise ExportError(f"{reader.path}: a joint state on {topic} lacks {', '.join(missing)}")
            rows.append(js["position"][[where[n] for n in names]])
        stamps.append(js["stamp_ns"])
    if names is None:
        return np.zeros(0, np.int64), (), np.zeros((0, 0))
    stamps, values = _in_stamp_order(stamps, np.asarray(rows, dtype=np.float64).reshape(len(rows), -1))
    return stamps, names, values


def _read_shapes(reader, topic: str | None, body_id: str) -> tuple:
    """``(stamp_ns, BodyShape)`` of ``body_id``'s body-shape messages, in stamp order."""
    from hmocap_ros.body.anthropometry import BodyShape
    from hmocap_ros.io.msg_factory import stamp_to_ns

    if topic is None:
        return ()
    shapes = []
    for item in reader.messages([topic]):
        msg = item.msg
        if str(msg.body_id) not in (body_id, ""):
            continue
        try:
            shape = BodyShape.from_named(msg.entity_names, msg.bone_scale, msg.radial_scale,
                                         msg.global_scale)
        except ValueError as err:
            raise ExportError(f"{reader.path}: the body shape on {topic}: {err}") from None
        shapes.append((stamp_to_ns(msg.header.stamp), shape))
    return tuple(sorted(shapes, key=lambda s: s[0]))


def read_motion(bag: str | Path, source: str = "tracked", body_id: str | None = None) -> BodyMotion:
    """The motion of one body (default: the first on the skeleton topic) of ``source``
    (:data:`MOTION_SOURCES`) in ``bag``.

    Raises:
        hmocap_ros.io.bag_reader.BagReadError: the bag is missing or cannot be read.
        ExportError: the bag has no skeleton of that source (the message lists its topics),
            or no body ``body_id`` (the message lists the body ids).
    """
    from hmocap_ros.io.bag_reader import BagReader

    kind = MOTION_SOURCES[source]
    with BagReader(bag) as reader:
        types = {t: info.msgtype for t, info in reader.topics().items()}
        skeleton = kind.skeleton_topic(types, reader.path)
        namespace = skeleton[:-len(kind.skeleton)]
        ids, chosen, stamps, points, names, parents = _read_skeletons(reader, skeleton, body_id)
        plain_shape = namespace + kind.body_shape
        first_shape = reader.first(plain_shape) if types.get(plain_shape) == BODY_SHAPE_TYPE else None
        first_id = str(first_shape.body_id) if first_shape is not None and first_shape.body_id else ids[0]
        is_first = chosen == first_id
        js_topic = kind.body_topic(types, namespace, kind.joint_states, JOINT_STATE_TYPE, chosen, is_first)
        shape_topic = kind.body_topic(types, namespace, kind.body_shape, BODY_SHAPE_TYPE, chosen, is_first)
        dof_stamps, dof_names, dofs = _read_joint_states(reader, js_topic)
        shapes = _read_shapes(reader, shape_topic, chosen)
    return BodyMotion(bag=Path(bag), source=source, body_id=chosen, stamps_ns=stamps,
                      point_names=names, parents=parents, points=points, dof_stamps_ns=dof_stamps,
                      dof_names=dof_names, dofs=dofs, shapes=shapes,
                      topics={"skeleton": skeleton, "joint_states": js_topic, "body_shape": shape_topic},
                      bag_topics=tuple(sorted(types)))
