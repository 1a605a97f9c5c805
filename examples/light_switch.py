"""light_switch: a gesture made near a place of the room toggles a light.

An example app on :mod:`hmocap_ros.client` (docs/client.md): when a gesture of ``gestures`` is
seen with its 3D point within ``near_m`` of ``place`` (from the ``places:`` of ``places_file``),
the light toggles; a gesture held over many frames toggles it once, and again only after
``cooldown_s`` without it.

Subscriptions: the Room's (``gestures``, ``skeleton``, ``humans/bodies/tracked``, ``camera_rig``,
``/tf_static``). Publications: ``light`` (std_msgs/Bool, latched: the light's state, off at the
start, then at each toggle). Parameters: ``light_switch --help``.
"""

from dataclasses import dataclass

from rclpy.node import Node
from std_msgs.msg import Bool

from hmocap_ros.client import OncePerHold, Room, declare_parameters, param, run_node
from hmocap_ros.client.room import LATCHED_QOS


@dataclass(frozen=True)
class LightSwitchConfig:
    places_file: str = param("", "YAML of the room's places (its places: section, in fixed_frame); empty: "
                                 "the package's config/places_example.yaml. Read again when it changes.")
    place: str = param("lamp", "The place a gesture must be made near.")
    gestures: list[str] = param(["pause"], "The gesture classes that toggle the light.")
    near_m: float = param(0.5, "(m) how near the place the gesture's 3D point must be.")
    cooldown_s: float = param(1.0, "(s, by the stamps) a gesture held counts once; it counts again after this "
                                   "long without it near the place.")
    fixed_frame: str = param("world", "The +Z-up frame of the places (REP 103).")


class Light:
    """The light and what toggles it (module docstring), without rclpy: the node feeds it the
    room's gestures."""

    def __init__(self, config: LightSwitchConfig, places):
        self.config = config
        self.places = places  # name -> place (PlacesFile), read again by the node when it changes
        self.first_of_hold = OncePerHold(int(config.cooldown_s * 1e9))
        self.on = False

    def on_gesture(self, gesture, room) -> str | None:
        """Toggle the light when ``gesture`` is one of ``gestures`` with its point within
        ``near_m`` of ``place`` and the first of a hold (by the stamps); the toggle's log line,
        naming the body whose hand made the gesture (``room.body_of``), or None when the light
        stays as it is."""
        place = self.places.get(self.config.place)
        if gesture.name not in self.config.gestures or gesture.point is None or place is None:
            return None
        if place.distance(gesture.point) > self.config.near_m or not self.first_of_hold(gesture.stamp_ns):
            return None
        self.on = not self.on
        body = room.body_of(gesture)
        return (f"light {'on' if self.on else 'off'}: {gesture.name} by {body.id if body else 'someone'} "
                f"near {self.config.place}")


class LightSwitch(Node):
    def __init__(self):
        super().__init__("light_switch")
        self.config = declare_parameters(self, LightSwitchConfig)
        self.room = Room(self, self.config.fixed_frame, on_gesture=self.on_gesture)
        places = self.room.load_places(self.config.places_file, "places")
        if places.get(self.config.place) is None and not places.errors:
            self.get_logger().warning(f"no place '{self.config.place}' in {places.path}: the light stays as it is")
        self.light = Light(self.config, places)
        self.pub = self.create_publisher(Bool, "light", LATCHED_QOS)
        self.pub.publish(Bool(data=self.light.on))
        self.get_logger().info(f"light off: {' or '.join(self.config.gestures)} near {self.config.place} toggles it")

    def on_gesture(self, gesture) -> None:
        line = self.light.on_gesture(gesture, self.room)
        if line is not None:
            self.pub.publish(Bool(data=self.light.on))
            self.get_logger().info(line)


def main(args=None) -> int:
    return run_node(LightSwitch, "light_switch", __doc__, LightSwitchConfig, args)


if __name__ == "__main__":
    raise SystemExit(main())
