"""Note when each message of some topics was published and when it arrived, for reaction times.

DDS stamps every sample with its writer's clock when it is published (``source_timestamp``)
and the reader's when it arrives (``received_timestamp``); on one host both are the system
clock of every process. Writes one JSON line per message: ``topic``, ``source_ns``,
``received_ns`` and ``cdr`` (the serialized message, hex). Logs ``monitor: matched`` once
every topic of ``--ready`` (default: all) has a publisher, and stops on Ctrl-C or SIGTERM.

    python -m hmocap_examples.monitor OUT.jsonl /gestures:hmocap_interfaces/msg/GestureArray \\
        /light:std_msgs/msg/Bool --latched /light --ready /light
"""

from __future__ import annotations

import argparse
import json

import rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from hmocap_ros.nodes.common import ShutdownFlag, message_class


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", help="JSON lines file to write")
    ap.add_argument("topics", nargs="+", metavar="TOPIC:TYPE", help="e.g. /light:std_msgs/msg/Bool")
    ap.add_argument("--latched", nargs="*", default=[], help="topics whose publishers are transient local")
    ap.add_argument("--ready", nargs="*", default=None, help="topics whose publishers it waits for (default: all)")
    ns = ap.parse_args(argv)
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    flag = ShutdownFlag()
    flag.install()
    node = Node("hmocap_monitor")
    with open(ns.out, "w") as out:
        def callback(topic: str):
            def noted(raw: bytes, info: dict) -> None:
                out.write(json.dumps({"topic": topic, "source_ns": info["source_timestamp"],
                                      "received_ns": info["received_timestamp"], "cdr": raw.hex()}) + "\n")
                out.flush()
            return noted

        subs = {}
        for spec in ns.topics:
            topic, msgtype = spec.split(":", 1)
            durability = DurabilityPolicy.TRANSIENT_LOCAL if topic in ns.latched else DurabilityPolicy.VOLATILE
            qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE, durability=durability)
            subs[topic] = node.create_subscription(message_class(msgtype), topic, callback(topic), qos, raw=True)
        waited = [subs[t] for t in (subs if ns.ready is None else ns.ready)]
        matched = False
        while not flag.requested and rclpy.ok():
            rclpy.spin_once(node, timeout_sec=0.05)
            if not matched and all(sub.get_publisher_count() > 0 for sub in waited):
                matched = True
                node.get_logger().info("monitor: matched")
        # what DDS delivered before the stop
        for _ in range(20):
            rclpy.spin_once(node, timeout_sec=0.0)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
