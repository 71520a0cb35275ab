"""robocore's fleet health probe: one ROS 2 observer of a robot's graph, run once on the robot (a Swarm task).

python3 fleet_probe.py --timeout S [--node /talker ...] [--heard /chatter ...]

Waits up to S seconds until every named node is in the graph and a message was heard on every named topic,
then prints one JSON line: {"ok": bool, "nodes": [...seen], "missing": [...], "heard": [...], "silent": [...]}.
While it waits it prints, every few seconds, a progress line {"waiting": true, "missing": [...], "silent":
[...]}: what the gate says it waits for.
Exit 0 when ok, 1 otherwise. The subscription is best effort and volatile, so it matches any publisher.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys
import time


#: Seconds between two progress lines ({"waiting": true, "missing": [...], "silent": [...]}).
PROGRESS = 5.0


def main() -> int:
    """Run the probe; print the verdict."""
    parser = argparse.ArgumentParser()
    parser.add_argument("--timeout", type=float, default=20.0)
    parser.add_argument("--node", action="append", default=[])
    parser.add_argument("--heard", action="append", default=[])
    args = parser.parse_args()

    import rclpy
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    rclpy.init()
    node = rclpy.create_node(f"_robocore_probe_{os.getpid()}", start_parameter_services=False)
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT, durability=DurabilityPolicy.VOLATILE)
    heard: set[str] = set()
    subscribed: set[str] = set()
    seen: set[str] = set()
    deadline = time.monotonic() + args.timeout
    said = time.monotonic()

    def on(topic: str):  # type: ignore[no-untyped-def]
        def received(_msg: object) -> None:
            heard.add(topic)
        return received

    while True:
        rclpy.spin_once(node, timeout_sec=0.1)
        seen = {f"{ns.rstrip('/')}/{name}" for name, ns in node.get_node_names_and_namespaces()}
        types = dict(node.get_topic_names_and_types())
        for topic in args.heard:
            if topic in subscribed or not types.get(topic):
                continue
            package, _, message = types[topic][0].replace("/msg/", "/").partition("/")
            try:
                msg_type = getattr(importlib.import_module(f"{package}.msg"), message)
            except (ImportError, AttributeError):
                continue
            node.create_subscription(msg_type, topic, on(topic), qos)
            subscribed.add(topic)
        missing = [n for n in args.node if n not in seen]
        silent = [t for t in args.heard if t not in heard]
        if (not missing and not silent) or time.monotonic() >= deadline:
            break
        if time.monotonic() >= said + PROGRESS:  # what it waits for, read by the gate while it runs
            print(json.dumps({"waiting": True, "missing": missing, "silent": silent}), flush=True)
            said = time.monotonic()
    verdict = {"ok": not missing and not silent, "nodes": sorted(n for n in seen if "/_" not in n),
               "missing": missing, "heard": sorted(heard), "silent": silent}
    print(json.dumps(verdict), flush=True)
    node.destroy_node()
    rclpy.shutdown()
    return 0 if verdict["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
