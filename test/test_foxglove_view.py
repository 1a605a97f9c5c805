"""``hmocap view``: live topics to Foxglove over its WebSocket protocol, on 127.0.0.1 only.

A publisher process sends ``sensor_msgs/JointState`` and ``hri_msgs/IdsList`` on loopback DDS;
``hmocap view`` offers them; a minimal WebSocket client written here (RFC 6455, the Foxglove SDK server's
``foxglove.sdk.v1`` subprotocol) reads the advertised channels, subscribes to one and
decodes the CDR bytes it receives with the advertised ``ros2msg`` schema (mcap-ros2-support's
decoder, as Foxglove decodes them). A client that connects and vanishes stalls nothing.
"""
from __future__ import annotations

import base64
import json
import os
import re
import socket
import struct
import sys
import time

from hmocap_ros.processes import NodeProcess, loopback_dds_env

PUBLISHER = r"""
import time, rclpy
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
from hri_msgs.msg import IdsList
rclpy.init()
node = rclpy.create_node("joints_source")
joints = node.create_publisher(JointState, "/joints", QoSProfile(depth=10))
tracked = node.create_publisher(IdsList, "/humans/bodies/tracked", QoSProfile(depth=10))
print("publishing", flush=True)
k = 0
while rclpy.ok():
    msg = JointState(name=["root_tx"], position=[float(k)])
    msg.header.frame_id = "room"
    joints.publish(msg)
    tracked.publish(IdsList(ids=["b0"]))
    k += 1
    rclpy.spin_once(node, timeout_sec=0.05)
"""


class WebSocket:
    """The client side of RFC 6455, enough for Foxglove's protocol: text and binary frames."""

    def __init__(self, port: int, protocol: str = "foxglove.sdk.v1"):
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=20)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall((f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
                           f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
                           f"Sec-WebSocket-Protocol: {protocol}\r\n\r\n").encode())
        head = b""
        while b"\r\n\r\n" not in head:
            head += self.sock.recv(1)
        assert b" 101 " in head.split(b"\r\n")[0], head

    def _read(self, n: int) -> bytes:
        data = b""
        while len(data) < n:
            chunk = self.sock.recv(n - len(data))
            assert chunk, "connection closed"
            data += chunk
        return data

    def receive(self) -> tuple[int, bytes]:
        """(opcode, payload) of the next data frame (fragments joined; pings answered)."""
        payload, first_opcode = b"", None
        while True:
            b0, b1 = self._read(2)
            opcode, length = b0 & 0x0F, b1 & 0x7F
            if length == 126:
                length = struct.unpack(">H", self._read(2))[0]
            elif length == 127:
                length = struct.unpack(">Q", self._read(8))[0]
            data = self._read(length)
            if opcode == 9:  # ping
                self._send(10, data)
                continue
            first_opcode = first_opcode if first_opcode is not None else opcode
            payload += data
            if b0 & 0x80:
                return first_opcode, payload

    def _send(self, opcode: int, data: bytes) -> None:
        mask = os.urandom(4)
        head = bytes([0x80 | opcode])
        n = len(data)
        head += bytes([0x80 | n]) if n < 126 else bytes([0x80 | 126]) + struct.pack(">H", n)
        self.sock.sendall(head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(data)))

    def send_json(self, obj) -> None:
        self._send(1, json.dumps(obj).encode())

    def close(self) -> None:
        self.sock.close()


def _start_view(tmp_path, env) -> tuple[NodeProcess, int]:
    view = NodeProcess.module("view", "hmocap_ros.cli", ["view", "--port", "0", "--period", "0.2"], env, tmp_path)
    assert view.wait_for_output("serving the ROS topics", 60), view.output()
    port = int(re.search(r"ws://127\.0\.0\.1:(\d+)", view.output()).group(1))
    return view, port


def _channels(ws: WebSocket, wanted: set[str], timeout: float = 60.0) -> dict[str, dict]:
    found: dict[str, dict] = {}
    end = time.monotonic() + timeout
    while time.monotonic() < end and not wanted <= set(found):
        opcode, payload = ws.receive()
        if opcode == 1:
            msg = json.loads(payload)
            if msg.get("op") == "advertise":
                found.update({c["topic"]: c for c in msg["channels"]})
    return found


def _listening_addresses(port: int) -> set[str]:
    """Local addresses with a TCP socket listening on ``port`` (from /proc/net/tcp and tcp6)."""
    out = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            lines = open(table).read().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            local, state = line.split()[1], line.split()[3]
            address, hex_port = local.split(":")
            if int(hex_port, 16) == port and state == "0A":  # LISTEN
                out.add(address)
    return out


def test_view_serves_live_topics_to_a_foxglove_client_on_loopback(tmp_path):
    from mcap_ros2._dynamic import generate_dynamic

    env = loopback_dds_env()
    source = NodeProcess("source", [sys.executable, "-c", PUBLISHER], env, tmp_path)
    view = None
    try:
        assert source.wait_for_output("publishing", 60), source.output()
        view, port = _start_view(tmp_path, env)
        assert _listening_addresses(port) == {"0100007F"}  # 127.0.0.1, nothing else
        ws = WebSocket(port)
        channels = _channels(ws, {"/joints", "/humans/bodies/tracked"})
        joints = channels["/joints"]
        assert (joints["encoding"], joints["schemaName"], joints["schemaEncoding"]) == \
            ("cdr", "sensor_msgs/msg/JointState", "ros2msg")
        assert channels["/humans/bodies/tracked"]["schemaName"] == "hri_msgs/msg/IdsList"
        subscribe = {"op": "subscribe", "subscriptions": [{"id": 7, "channelId": joints["id"]}]}
        ws.send_json(subscribe)
        decode = generate_dynamic(joints["schemaName"], joints["schema"])[joints["schemaName"]]
        positions = []
        end = time.monotonic() + 60
        while len(positions) < 5 and time.monotonic() < end:
            try:
                opcode, payload = ws.receive()
            except TimeoutError:
                raise AssertionError(view.output()) from None
            if opcode == 1 and "Unknown channel" in json.loads(payload).get("message", ""):
                # foxglove-sdk 0.30 may advertise a channel created while the client connects
                # before it accepts subscriptions to it: a client asks again
                time.sleep(0.2)
                ws.send_json(subscribe)
            if opcode == 2 and payload[0] == 1:  # message data: op, subscription id, log time, CDR
                subscription, = struct.unpack("<I", payload[1:5])
                assert subscription == 7
                msg = decode(payload[13:])
                assert list(msg.name) == ["root_tx"] and msg.header.frame_id == "room"
                positions.append(msg.position[0])
        assert len(positions) == 5 and positions == sorted(positions), positions
        ws.close()
        # a viewer that connects and vanishes without a word: the bridge and the source go on
        for _ in range(3):
            WebSocket(port).close()
        again = WebSocket(port)
        assert "/joints" in _channels(again, {"/joints"})
        again.close()
        assert view.proc.poll() is None and source.proc.poll() is None
    finally:
        if view is not None:
            view.stop()
        source.stop()
    log = view.output()
    assert "Traceback" not in log and "a viewer watches /joints" in log, log


def test_view_refuses_a_port_in_use(tmp_path, capsys):
    from hmocap_ros.cli import main

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        assert main(["view", "--port", str(port)]) == 2
    err = capsys.readouterr().err
    assert f"127.0.0.1:{port}" in err and len(err.strip().splitlines()) == 1, err
