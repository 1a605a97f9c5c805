"""ROS topics as channels of a Foxglove WebSocket server (``foxglove-sdk``), without rclpy.

:class:`FoxgloveBridge` starts Foxglove's server (the ``foxglove-sdk`` package from the
package index) on ``127.0.0.1`` by default, so Foxglove (the desktop app or the browser,
"Open connection" -> ``ws://127.0.0.1:8765``) shows the room with no ROS install on the
viewing side. Each topic is one channel: its messages go out as the CDR bytes DDS delivered
(``message_encoding`` ``cdr``), described by the ``ros2msg`` schema of its type
(:func:`ros2msg_schema`, the concatenated ``.msg`` definitions a rosbag2 MCAP file stores),
which Foxglove decodes itself: images, camera_info, markers, TF, skeletons and gestures keep
their types, and Foxglove's panels draw them as from a bag.

Only what a viewer watches is carried: :meth:`FoxgloveBridge.watched` is the set of topics
some connected client subscribed to, and the ROS side (:mod:`hmocap_ros.nodes.foxglove_view`)
subscribes to exactly those. The server sends to each client from its own queue and drops
what a slow client cannot take, so a viewer that connects, lags or disconnects never
holds up the bridge, let alone a node.
"""

from __future__ import annotations

import logging
import threading
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from foxglove import Channel

__all__ = ["DEFAULT_HOST", "DEFAULT_PORT", "FoxgloveBridge", "ros2msg_schema"]

log = logging.getLogger(__name__)

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765


def ros2msg_schema(typename: str) -> str:
    """The ``ros2msg`` schema of ``typename`` (``sensor_msgs/msg/Image``): its definition, then
    each type it uses after a line of ``=`` and ``MSG: pkg/Name``. KeyError for a type the
    package's type store does not know (:func:`hmocap_ros.io.typestore.hmocap_typestore`:
    ROS 2 Jazzy's standard types, hmocap_interfaces, hri_msgs)."""
    from hmocap_ros.io.typestore import hmocap_typestore

    store = hmocap_typestore()
    if typename not in store.fielddefs:
        raise KeyError(typename)
    text, _digest = store.generate_msgdef(typename, ros_version=2)
    return text


class _Listener:
    """Keeps the count of client subscriptions per topic (called from the server's threads)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.clients: dict[str, set[int]] = {}

    def on_subscribe(self, client, channel) -> None:
        with self.lock:
            self.clients.setdefault(channel.topic, set()).add(client.id)

    def on_unsubscribe(self, client, channel) -> None:
        with self.lock:
            self.clients.get(channel.topic, set()).discard(client.id)

    def watched(self) -> set[str]:
        with self.lock:
            return {topic for topic, ids in self.clients.items() if ids}


class FoxgloveBridge:
    """A Foxglove WebSocket server with one channel per advertised ROS topic (module docstring).

    host, port: where the server listens (127.0.0.1: this machine only; port 0 picks a free
    one, :attr:`port` says which). ``OSError`` when the port is taken.
    """

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, name: str = "hmocap_ros"):
        import foxglove

        self._foxglove = foxglove
        self._listener = _Listener()
        try:
            self.server = foxglove.start_server(name=name, host=host, port=port,
                                                # _Listener has only the protocol's subscription callbacks
                                                server_listener=self._listener)  # type: ignore[arg-type]
        except RuntimeError as err:  # the SDK reports a taken port as a RuntimeError
            raise OSError(f"cannot serve Foxglove on {host}:{port}: {err}") from err
        self.host = host
        self.channels: dict[str, Channel] = {}

    @property
    def port(self) -> int:
        return int(self.server.port)

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def advertise(self, topic: str, typename: str) -> bool:
        """Offer ``topic`` of ROS type ``typename`` to the clients; False (nothing offered) for a
        type without a known definition."""
        if topic in self.channels:
            return True
        try:
            schema = ros2msg_schema(typename)
        except KeyError:
            return False
        self.channels[topic] = self._foxglove.Channel(
            topic, message_encoding="cdr",
            schema=self._foxglove.Schema(name=typename, encoding="ros2msg", data=schema.encode()))
        return True

    def remove(self, topic: str) -> None:
        """Stop offering ``topic`` (its publishers are gone)."""
        channel = self.channels.pop(topic, None)
        if channel is not None:
            channel.close()

    def watched(self) -> set[str]:
        """The advertised topics some connected client subscribes to."""
        return self._listener.watched() & set(self.channels)

    def log(self, topic: str, data: bytes, log_time_ns: int) -> None:
        """Send one CDR-serialised message of ``topic`` to the clients that subscribe to it."""
        channel = self.channels.get(topic)
        if channel is not None:
            channel.log(bytes(data), log_time=int(log_time_ns))

    def close(self) -> None:
        for topic in list(self.channels):
            self.remove(topic)
        self.server.stop()
