"""Updates only at a safe moment on the Swarm suite's robots: a robot's own node holding its update lock, and
maintenance windows written into a fleet's file.

The lock is held by a real rclpy node on the robot: a second process in the robot's running talker container
(``docker exec`` on the robot host, so it has the robot's discovery server, DDS profile and shared memory as any
node of the robot has), publishing ``true`` on ``/robocore/update_lock`` latched (reliable, transient local), as
docs/fleets.md tells a team to. It releases the lock by publishing ``false`` when a file appears, and marks each
step with a file of its own, so that the test waits on the events, not on sleeps.
"""

from __future__ import annotations

from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any

import yaml
from deploy_helpers import wait_for
from robot_host.hosts import RobotFleet

from robocore.plan.starts import docker_epoch

HELD, RELEASE, RELEASED = "/tmp/robocore-lock-held", "/tmp/robocore-lock-release", "/tmp/robocore-lock-released"
#: The node a robot's mission would run (docs/fleets.md's three lines, and a wait for the end of the mission).
HOLDER = f"""
import os, rclpy
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_msgs.msg import Bool
rclpy.init()
node = rclpy.create_node("mission")
qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
lock = node.create_publisher(Bool, "/robocore/update_lock", qos)
lock.publish(Bool(data=True))
open("{HELD}", "w").close()
while not os.path.exists("{RELEASE}"):
    rclpy.spin_once(node, timeout_sec=0.1)
lock.publish(Bool(data=False))
open("{RELEASED}", "w").close()
rclpy.spin(node)
"""


def talker(hosts: RobotFleet, index: int, service: str) -> tuple[str, float]:
    """The running container of ``service`` on host ``index``: its id and when it started (epoch seconds)."""
    out = hosts.hosts[index].ssh(hosts, "sh", "-c", "docker ps -q --filter label=com.docker.swarm.service.name=$1 | "
                                 "xargs -r docker inspect --format '{{.Id}} {{.State.StartedAt}}'", "sh", service)
    lines = out.split("\n", 1)[0].split()
    assert len(lines) == 2, out
    return lines[0], docker_epoch(lines[1])


def _has(hosts: RobotFleet, index: int, container: str, path: str) -> bool:
    out = hosts.hosts[index].ssh(hosts, "sh", "-c", 'docker exec "$1" test -f "$2" && echo yes', "sh", container, path,
                                 check=False)
    return out.strip() == "yes"


def hold_lock(hosts: RobotFleet, index: int, service: str) -> str:
    """Start the lock holder in ``service``'s running container on host ``index``; once it has published ``true``,
    the container's id."""
    container, _ = talker(hosts, index, service)
    hosts.hosts[index].ssh(hosts, "docker", "exec", "-d", container, "/robocore/entrypoint.sh", "python3", "-c", HOLDER)
    assert wait_for(lambda: _has(hosts, index, container, HELD), 60), "the lock holder never published"
    return container


def release_lock(hosts: RobotFleet, index: int, container: str) -> float:
    """Have the holder publish ``false``; when it did (epoch seconds, this machine's clock, which the hosts share)."""
    hosts.hosts[index].ssh(hosts, "docker", "exec", container, "touch", RELEASE)
    assert wait_for(lambda: _has(hosts, index, container, RELEASED), 30), "the lock holder never released"
    out = hosts.hosts[index].ssh(hosts, "docker", "exec", container, "stat", "-c", "%.9Y", RELEASED)
    return float(out.strip())


def closed_window() -> tuple[datetime, dict[str, Any]]:
    """A maintenance window (UTC, every day) that is closed now: from the hour two hours from now, for an hour; and
    when it opens next (one to two hours from now)."""
    opens = (datetime.now(timezone.utc) + timedelta(hours=2)).replace(minute=0, second=0, microsecond=0)
    return opens, {"from": f"{opens:%H}:00", "to": f"{(opens + timedelta(hours=1)):%H}:00", "timezone": "UTC"}


def set_rollout(root: Path, **rollout: Any) -> str:
    """Update the ``rollout`` keys of ``root``'s fleet.yaml (``timeouts`` merged into its own); the text before."""
    path = root / "fleet.yaml"
    original = path.read_text()
    data = yaml.safe_load(original)
    timeouts = rollout.pop("timeouts", {})
    data["rollout"].update(rollout)
    data["rollout"]["timeouts"].update(timeouts)
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return original
