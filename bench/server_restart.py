"""A single discovery server's restart: when a node started after it is heard, the ways out side by side in one run.

One Docker network, four containers of a wheels base image: a discovery server started as robocore starts it
(its command, profile and state volume, from :mod:`robocore.plan.discovery.fastdds`), a talker (rclpy, 10 Hz), a
watcher (a listener matched before the restart, which counts the talker's messages it missed across it) and, for
each measurement, a fresh listener, all clients with robocore's client profile. For each way of restarting the
server (stopped, SIGKILL unless said, and started again at once), a listener is started right after the start
and the time until it hears the talker is printed ("NOTHING" after ``--wait`` seconds plus the hold), beside a
control listener started before the restart and the watcher's count.

Fast DDS 2.x (``--distro jazzy``, the default; Fast DDS 2.14):

- ``same GUID, no hold``: the server comes back at once with its old GUID (its ``-i``);
- ``BACKUP (-b)``: the server keeps its discovery database in files in its state volume and reloads them on
  restart (Fast DDS's own remedy for restarts), after a SIGTERM or a SIGKILL stop;
- ``same GUID, hold N s``: what robocore does: the restarted server stays silent for N s (default 12: its
  clients' 8 s lease of the server, plus 4 s) so that every client drops the old instance first; and
  shorter holds, to show where recovery stops.

Fast DDS 3.x (``--distro kilted`` and a Kilted wheels base as ``--image``; Fast DDS 3.2): the server is started
without ``-i``, as robocore starts it there, so it has a new GUID at every start and robocore holds nothing. A
client matches the new server's discovery endpoints only once it dropped the killed one, so the server's lease
decides: the rows are robocore's lease (after a SIGKILL and after a SIGTERM stop), the 8 s lease 2.x keeps, and
the same server given a fixed GUID (``-i 0``, as 2.x must). A run of another distro than Jazzy is written to
``bench/results/server_restart-<distro>.json``. ``--repeat`` runs each row that many times.

    python bench/server_restart.py [--distro jazzy] [--image IMAGE] [--wait 30] [--hold 12] [--repeat 1]

The image is any wheels base of the distro robocore built (the integration suites build ``robocore-it-demo-base``
for Jazzy and ``robocore-it-kilted-base`` for Kilted).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import docker
from docker.errors import ImageNotFound, NotFound
from harness import Figure, record

from robocore.config.model import Robot
from robocore.plan.discovery import fastdds

PREFIX = "robocore-it-dsprobe"
SUBNET, SERVER_IP, TALKER_IP, LISTENER_IP = "172.31.78.0/24", "172.31.78.10", "172.31.78.11", "172.31.78.12"
WATCHER_IP = "172.31.78.13"
#: The wheels base the integration suites build, per distro: the default ``--image``.
IMAGES = {"jazzy": "robocore-it-demo-base:latest", "kilted": "robocore-it-kilted-base:latest"}
#: The lease 2.x servers keep (8 s, announced every 2 s), measured on 3.x for contrast.
LEASE_8S = fastdds.ServerLiveliness(lease_ms=8000, announcement_ms=2000, hold_seconds=0)


def robot_of(distro: str) -> Robot:
    """A one-host robot of ``distro`` whose server is at SERVER_IP (robocore's own commands and profiles for it)."""
    return Robot.model_validate({"ros_distro": distro, "hosts": [{"name": "main", "ip": SERVER_IP}], "components": []})


DDS_DIR = "/robocore/dds"  # where CLIENT_ENV's profile file is (robocore's layout in containers)
TALKER = """
import rclpy
from std_msgs.msg import String
rclpy.init()
node = rclpy.create_node("talker")
pub = node.create_publisher(String, "chatter", 10)
count = [0]
def tick():
    count[0] += 1
    pub.publish(String(data=f"hello {count[0]}"))
node.create_timer(0.1, tick)
rclpy.spin(node)
"""
LISTENER = """
import sys, time
import rclpy
from std_msgs.msg import String
start = time.monotonic()
rclpy.init()
node = rclpy.create_node("listener")
heard = []
node.create_subscription(String, "chatter", lambda m: heard.append(time.monotonic() - start), 10)
while not heard and time.monotonic() - start < float(sys.argv[1]):
    rclpy.spin_once(node, timeout_sec=0.1)
print(f"HEARD {heard[0]:.2f}" if heard else "NOTHING", flush=True)
"""
#: A listener left running across the restart: every second, the talker's messages it got, the numbers it missed
#: between its first and its last, and the longest silence between two of them.
WATCHER = """
import time
import rclpy
from std_msgs.msg import String
rclpy.init()
node = rclpy.create_node("watcher")
seen, last, gap = set(), [None], [0.0]
def got(msg):
    now = time.monotonic()
    if last[0] is not None:
        gap[0] = max(gap[0], now - last[0])
    last[0] = now
    seen.add(int(msg.data.split()[1]))
node.create_subscription(String, "chatter", got, 10)
def report():
    missed = max(seen) - min(seen) + 1 - len(seen) if seen else 0
    print(f"WATCHED {len(seen)} missed {missed} longest silence {gap[0]:.2f} s", flush=True)
node.create_timer(1.0, report)
rclpy.spin(node)
"""


@contextlib.contextmanager
def network(client: Any) -> Iterator[Any]:
    ipam = docker.types.IPAMConfig(pool_configs=[docker.types.IPAMPool(subnet=SUBNET)])
    net = client.networks.create(f"{PREFIX}-net", ipam=ipam)
    try:
        yield net
    finally:
        for container in client.containers.list(all=True, filters={"name": PREFIX}):
            container.remove(force=True)
        net.remove()
        for volume in client.volumes.list(filters={"name": PREFIX}):
            volume.remove(force=True)


def start(client: Any, net: Any, image: str, name: str, ip: str, argv: list[str],
          env: dict[str, str] | None = None, **kwargs: Any) -> Any:
    container = client.containers.create(image, argv, name=f"{PREFIX}-{name}", environment=env or {},
                                         detach=True, **kwargs)
    client.networks.get("bridge").disconnect(container)
    net.connect(container, ipv4_address=ip)
    container.start()
    return container


def client_node(client: Any, net: Any, image: str, name: str, ip: str, argv: list[str], dds: str,
                robot: Robot) -> Any:
    """A node started as robocore starts components: robocore's client environment and profile."""
    env = fastdds.client_environment(robot)
    return start(client, net, image, name, ip, argv, env, volumes={dds: {"bind": DDS_DIR, "mode": "ro"}})


def listen(client: Any, net: Any, image: str, wait: float, dds: str, robot: Robot) -> tuple[str, float]:
    """A new listener's verdict, ``HEARD <s>`` (seconds from its Python's start) or ``NOTHING``, and when this
    process saw it (``time.monotonic()``, its logs read every 0.1 s): a listener slow to start under load shows
    in the second, not in the first."""
    argv = ["python3", "-c", LISTENER, str(wait)]
    container = client_node(client, net, image, "listener", LISTENER_IP, argv, dds, robot)
    try:
        deadline = time.monotonic() + wait + 60
        while time.monotonic() < deadline:
            words = container.logs(stdout=True, stderr=False).decode(errors="replace").split()
            if "HEARD" in words:
                seen = time.monotonic()
                return " ".join(words[words.index("HEARD"):][:2]), seen
            if "NOTHING" in words:
                break
            time.sleep(0.1)
        return "NOTHING", time.monotonic()
    finally:
        container.remove(force=True)


def watched(container: Any) -> str:
    """The watcher's last report: messages got, missed across the restart, and the longest silence."""
    lines = [line for line in container.logs(stdout=True, stderr=False).decode(errors="replace").splitlines()
             if line.startswith("WATCHED")]
    return lines[-1].removeprefix("WATCHED ") if lines else "watcher heard nothing"


def scenario(client: Any, image: str, wait: float, dds: str, robot: Robot, *, backup: bool, hold: int,
             stop_timeout: int, fixed_id: bool = False,
             liveliness: fastdds.ServerLiveliness | None = None) -> dict[str, str]:
    with network(client) as net:
        process = fastdds.server_process(robot, 0)
        env = {**process.environment, "ROBOCORE_DS_HOLD": str(hold)}
        if liveliness is not None:  # another lease than robocore's, for contrast
            env["ROBOCORE_DS_XML"] = fastdds.server_profile_xml(robot, liveliness)
        state = {f"{PREFIX}-state": {"bind": process.state_dir, "mode": "rw"}}  # a volume: it outlives a restart
        argv = list(process.command)
        if fixed_id and "-i" not in argv:  # 3.x: the same GUID at every start, as 2.x has
            argv[argv.index("discovery") + 1:argv.index("discovery") + 1] = ["-i", "0"]
        argv += ["-b"] if backup else []  # -b: the backup files go to the state volume
        server = start(client, net, image, "server", SERVER_IP, argv, env, volumes=state, working_dir=process.state_dir)
        time.sleep(2)
        client_node(client, net, image, "talker", TALKER_IP, ["python3", "-c", TALKER], dds, robot)
        watcher = client_node(client, net, image, "watcher", WATCHER_IP, ["python3", "-c", WATCHER], dds, robot)
        time.sleep(4)
        before, _ = listen(client, net, image, wait, dds, robot)
        stopping = time.monotonic()
        server.stop(timeout=stop_timeout)
        stopped = time.monotonic()
        server.start()
        after, seen = listen(client, net, image, wait + hold, dds, robot)
        time.sleep(1.5)  # the watcher's next report
        watch = watched(watcher)
        server.reload()
        logs = server.logs().decode(errors="replace")
        crashed = next((line.strip() for line in logs.splitlines() if "malloc" in line or "corrupt" in line), "")
        status = f"{server.status}" + (f", {crashed}" if crashed else "")
        if after.startswith("HEARD"):
            after = f"HEARD {float(after.split()[1]):.1f} s after its start, {seen - stopped:.1f} s after the stop"
        after += f" (stop took {stopped - stopping:.1f} s)"
        return {"before": before, "after": after, "server": status, "watcher": watch}


def rows_of(robot: Robot, hold: int) -> dict[str, dict[str, Any]]:
    """The ways of restarting the server measured on ``robot``'s Fast DDS line: label -> :func:`scenario`'s options."""
    if robot.fastdds_line >= 3:  # a new GUID at every start (no -i): robocore holds nothing
        live = fastdds.server_liveliness(robot)
        lease = f"lease {live.lease_ms / 1000:g} s"
        return {
            f"new GUID, {lease} (robocore), SIGKILL stop": dict(backup=False, hold=0, stop_timeout=0),
            f"new GUID, {lease} (robocore), SIGTERM stop": dict(backup=False, hold=0, stop_timeout=10),
            "new GUID, lease 8 s (2.x's), SIGKILL stop": dict(backup=False, hold=0, stop_timeout=0,
                                                              liveliness=LEASE_8S),
            "same GUID (-i 0), no hold, SIGKILL stop": dict(backup=False, hold=0, stop_timeout=0, fixed_id=True),
        }
    return {
        "same GUID, no hold": dict(backup=False, hold=0, stop_timeout=0),
        "BACKUP server (-b), SIGTERM stop": dict(backup=True, hold=0, stop_timeout=10),
        "BACKUP server (-b), SIGKILL stop": dict(backup=True, hold=0, stop_timeout=0),
        f"same GUID, hold {hold} s (robocore)": dict(backup=False, hold=hold, stop_timeout=0),
        f"same GUID, hold {hold // 2} s": dict(backup=False, hold=hold // 2, stop_timeout=0),
        f"same GUID, hold {hold // 3} s": dict(backup=False, hold=hold // 3, stop_timeout=0),
    }


def seconds_of(after: str) -> tuple[float, float]:
    """The seconds of a ``HEARD <a> s after its start, <b> s after the stop`` verdict; infinity for ``NOTHING``."""
    if not after.startswith("HEARD"):
        return math.inf, math.inf
    words = after.split()
    return float(words[1]), float(words[6])


#: The goal of a node started after a 3.x server's restart: heard within 5 s. Judged from the server's
#: stop, which also counts the node's own start (a container and Python).
GOAL_3X = 5.0


def median_figure(label: str, heard: list[tuple[float, float]], robot: Robot) -> Figure:
    """A row's median over its runs, from the server's stop (a run that never heard counts as the longest),
    judged against :data:`GOAL_3X` for robocore's own 3.x rows; the medians from the listener's start in detail."""
    stop = statistics.median(h[1] for h in heard)
    start = statistics.median(h[0] for h in heard)
    never = sum(not math.isfinite(h[1]) for h in heard)
    detail = (f"{len(heard)} runs, from the stop: " + ", ".join(f"{h[1]:.1f}" if math.isfinite(h[1]) else "never"
                                                               for h in heard)
              + (f" ({never} never heard)" if never else "")
              + (f"; median from the listener's start {start:.1f} s" if math.isfinite(start) else ""))
    judged = robot.fastdds_line >= 3 and "(robocore)" in label
    return Figure(f"median from the stop: {label}", round(stop, 2) if math.isfinite(stop) else "NOTHING",
                  "s" if math.isfinite(stop) else "", goal=f"< {GOAL_3X:g} s" if judged else None,
                  met=bool(stop < GOAL_3X) if judged else None, detail=detail)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--image", help="a wheels base of the distro (default: the integration suites' own)")
    parser.add_argument("--distro", default="jazzy", help="the image's ROS 2 distro (kilted: Fast DDS 3.x)")
    parser.add_argument("--wait", type=float, default=30.0)
    parser.add_argument("--hold", type=int, help="robocore's hold (default: robocore's, for the distro)")
    parser.add_argument("--repeat", type=int, default=1, help="runs of each way")
    args = parser.parse_args()
    robot = robot_of(args.distro)
    args.image = args.image or IMAGES.get(args.distro, f"robocore-it-{args.distro}-base:latest")
    hold = fastdds.restart_hold_seconds(robot) if args.hold is None else args.hold
    client = docker.from_env()
    try:
        client.images.get(args.image)
    except ImageNotFound:
        raise SystemExit(f"{args.image}: no such image (run the integration suites or pass --image)") from None
    dds = tempfile.mkdtemp(prefix=f"{PREFIX}-")
    for name, text in fastdds.profile_files(robot).items():
        (Path(dds) / name).write_text(text)
    os.chmod(dds, 0o755)
    print(f"{args.distro} (Fast DDS {robot.fastdds_line}.x), {args.image}; robocore's hold: {hold} s")
    print(f"{'restart':44} {'listener before':16} {'listener after the restart':56} server after; watcher")
    figures, medians = [], []
    for label, kwargs in rows_of(robot, hold).items():
        heard = []
        for _ in range(args.repeat):
            with contextlib.suppress(NotFound):
                done = scenario(client, args.image, args.wait, dds, robot, **kwargs)
                print(f"{label:44} {done['before']:16} {done['after']:56} {done['server']}; {done['watcher']}",
                      flush=True)
                figures.append(Figure(label, done["after"], detail=f"listener before: {done['before']}; server "
                                                                   f"after: {done['server']}; watcher (matched "
                                                                   f"before): {done['watcher']}"))
                heard.append(seconds_of(done["after"]))
        if len(heard) > 1:
            medians.append(median_figure(label, heard, robot))
    figures += medians
    record("server_restart", figures, variant="" if args.distro == "jazzy" else args.distro,
           notes=[f"{args.distro} (Fast DDS {robot.fastdds_line}.x), image {args.image}; a listener waits "
                  f"{args.wait:g} s (plus the hold) to hear the talker after the restart; the watcher, a listener "
                  "matched before the restart, counts the talker's messages it missed across it"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
