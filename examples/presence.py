"""presence: who is in which zone of the room.

An example app on :mod:`hmocap_ros.client` (docs/client.md): every tracked body is placed in the
zones (``zones:`` of ``zones_file``) that hold its position (its pelvis); it leaves a zone once
``margin_m`` outside it, or when the body is lost.

Subscriptions: the Room's (``skeleton``, ``humans/bodies/tracked``, ``gestures``, ``camera_rig``,
``/tf_static``). Publications: ``presence`` (diagnostic_msgs/DiagnosticArray, latched, at the start
and at every change: one status per zone, ``name`` the zone, ``message`` the ids of the bodies in
it in the order they came in, one key-value per body, its id and the stamp (ns) it came in at;
``header.stamp`` is the stamp of the pose or tracked list that made the change).
Parameters: ``presence --help``.
"""

from dataclasses import dataclass

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.time import Time

from hmocap_ros.client import Room, declare_parameters, param, run_node, zones_containing
from hmocap_ros.client.room import LATCHED_QOS


@dataclass(frozen=True)
class PresenceConfig:
    zones_file: str = param("", "YAML of the room's zones (its zones: section, in fixed_frame); empty: the "
                                "package's config/places_example.yaml. Read again when it changes.")
    margin_m: float = param(0.15, "(m) a body stays in a zone until it is this far outside it.")
    lost_after_s: float = param(10.0, "(s) a body tracker silent this long loses every body (0: never).")
    fixed_frame: str = param("world", "The +Z-up frame of the zones (REP 103).")


class Presence(Node):
    def __init__(self):
        super().__init__("presence")
        self.config = declare_parameters(self, PresenceConfig)
        self.room = Room(self, self.config.fixed_frame, self.config.lost_after_s,
                         on_body=self.on_body, on_body_lost=self.on_body_lost)
        self.zones = self.room.load_places(self.config.zones_file, "zones")
        self.inside: dict[str, dict[str, int]] = {}  # zone -> {body id: stamp it came in at}
        self.pub = self.create_publisher(DiagnosticArray, "presence", LATCHED_QOS)
        self.publish(self.get_clock().now().nanoseconds)

    def on_body(self, body) -> None:
        was = {zone for zone, ids in self.inside.items() if body.id in ids}
        self.update(body.id, was, zones_containing(body.position, self.zones, was, self.config.margin_m), body.stamp_ns)

    def on_body_lost(self, body_id: str) -> None:
        self.update(body_id, {zone for zone, ids in self.inside.items() if body_id in ids}, set(), self.room.stamp_ns)

    def update(self, body_id: str, was: set, now: set, stamp_ns: int) -> None:
        for zone in sorted(was - now):
            del self.inside[zone][body_id]
            self.get_logger().info(f"{body_id} left {zone}")
        for zone in sorted(now - was):
            self.inside.setdefault(zone, {})[body_id] = stamp_ns
            self.get_logger().info(f"{body_id} came into {zone}")
        if was != now:
            self.publish(stamp_ns)

    def publish(self, stamp_ns: int) -> None:
        msg = DiagnosticArray()
        msg.header.stamp, msg.header.frame_id = Time(nanoseconds=stamp_ns).to_msg(), self.config.fixed_frame
        for zone, _ in self.zones.items():
            ids = self.inside.get(zone, {})
            msg.status.append(DiagnosticStatus(name=zone, message=" ".join(ids),
                                               values=[KeyValue(key=b, value=str(t)) for b, t in ids.items()]))
        self.pub.publish(msg)


def main(args=None) -> int:
    return run_node(Presence, "presence", __doc__, PresenceConfig, args)


if __name__ == "__main__":
    raise SystemExit(main())
