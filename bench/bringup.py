"""Bring-up of a whole robot: ``robocore run`` of N components on H robot hosts, to running and to all heard.

A robot of N talkers (the template's talker, one component each, spread round-robin over H simulated robot
hosts, one Fast DDS discovery server on the first) is staged, built, synced and run once (which puts its images
on the hosts); then, ``--repeat`` times:
``robocore down``, a probe process started (a super client of the robot's server, as the pytest plugin's probe
is), and ``robocore run`` timed:

- **running**: from starting ``robocore run`` to its exit (it returns once every container is created and
  started, the discovery server answering first);
- **all heard**: from starting ``robocore run`` until the probe has taken a message from each of the N
  talkers (counted by their publishers' GIDs, so N identical programs are N talkers).

Goals: 16 components on 3 hosts running in < 3 s and all heard in < 5 s; 64 components on 4 hosts running in
< 10 s.

    python bench/bringup.py [--shapes 16x3 64x4] [--repeat 3]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml
from harness import Figure, record, robocore
from robot_host.hosts import RobotFleet

PROBE = r"""
import json, sys, time
import rclpy
from std_msgs.msg import String

expected = int(sys.argv[1])
rclpy.init()
node = rclpy.create_node("bringup_probe")
seen = {}

def heard(msg, info):
    gid = bytes(info["publisher_gid"]["data"]).hex() if isinstance(info["publisher_gid"], dict) else repr(
        info["publisher_gid"])
    if gid not in seen:
        seen[gid] = time.time()
        print(json.dumps({"talkers": len(seen), "at": seen[gid]}), flush=True)

node.create_subscription(String, "chatter", heard, 100)
print(json.dumps({"ready": time.time()}), flush=True)
deadline = time.time() + float(sys.argv[2])
while len(seen) < expected and time.time() < deadline:
    rclpy.spin_once(node, timeout_sec=0.1)
"""

GOALS = {"16x3": (3.0, 5.0), "64x4": (10.0, None)}


def make_project(scratch: Path, components: int, fleet: RobotFleet) -> Path:
    """The template project with ``components`` talkers spread over the fleet's hosts, built and synced."""
    root = scratch / f"bringup-{components}x{len(fleet.hosts)}"
    robocore(None, "init", str(root), "--defaults", "--base", "wheels")
    data = yaml.safe_load((root / "robot.yaml").read_text())
    talker = next(c for c in data["components"] if c["name"] == "talker")
    names = [f"h{i}" for i in range(len(fleet.hosts))]
    data["hosts"] = yaml.safe_load(fleet.host_yaml(names))
    data["discovery"] = {"servers": [{"host": names[0], "port": 11811}]}
    data["components"] = [{**talker, "name": f"talker{i}", "runs_on": names[i % len(names)]}
                          for i in range(components)]
    (root / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    for step in ("prepare-base", "stage", "build", "sync", "run"):  # the first run puts the images on the hosts
        robocore(root, step, "--quiet", timeout=1800)
    return root


def probe_env(root: Path) -> dict[str, str]:
    """The environment of a super client of the project's servers (UDP), its profile written under ``root``."""
    from robocore.plan import testrun
    from robocore.project import Project

    project = Project.load(root)
    profile = root / ".robocore" / "bringup-probe.xml"
    profile.write_text(testrun.probe_profile(project.robot))
    env = {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "FASTDDS_", "FASTRTPS_"))}
    env.update(testrun.probe_environment(project.robot, str(profile)))
    env.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    return env


def one_bring_up(root: Path, components: int, env: dict[str, str], timeout: float = 60) -> tuple[float, float | None]:
    """``robocore down``, then ``robocore run`` timed: (seconds to its exit, seconds until every talker heard)."""
    robocore(root, "down", "--quiet")
    probe = subprocess.Popen([sys.executable, "-c", PROBE, str(components), str(timeout)], env=env,
                             stdout=subprocess.PIPE, text=True)
    assert probe.stdout is not None
    json.loads(probe.stdout.readline())  # its node exists: what is heard from now on counts
    start = time.time()
    robocore(root, "run", "--quiet")
    running = time.time() - start
    last = None
    for line in probe.stdout:
        event = json.loads(line)
        if event.get("talkers") == components:
            last = event["at"] - start
    probe.wait(timeout=timeout + 10)
    return running, last


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--shapes", nargs="+", default=["16x3", "64x4"], help="COMPONENTSxHOSTS")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    rows: list[Figure] = []
    print(f"{'robot':<28}{'running s':>12}{'all heard s':>14}   runs")
    with tempfile.TemporaryDirectory(prefix="robocore-bench-bringup-") as scratch:
        for shape in args.shapes:
            components, hosts = (int(x) for x in shape.split("x"))
            with RobotFleet(hosts, tag=f"bu{components}") as fleet:
                root = make_project(Path(scratch), components, fleet)
                env = probe_env(root)
                runs = [one_bring_up(root, components, env) for _ in range(args.repeat)]
                robocore(root, "down", "--quiet")
            running = statistics.median(r for r, _ in runs)
            heard_all = [h for _, h in runs if h is not None]
            heard = statistics.median(heard_all) if len(heard_all) == len(runs) else None
            shown = ", ".join(f"{r:.2f}/{'-' if h is None else f'{h:.2f}'}" for r, h in runs)
            print(f"{f'{components} components on {hosts} hosts':<28}{running:>12.2f}"
                  f"{'-' if heard is None else f'{heard:.2f}':>14}   {shown}")
            goal_running, goal_heard = GOALS.get(shape, (None, None))
            label = f"{components} components on {hosts} hosts"
            rows.append(Figure(f"{label}: running", running, "s", f"< {goal_running:g} s" if goal_running else None,
                               met=running < goal_running if goal_running else None,
                               detail=f"median of {len(runs)}; runs (running/all heard): {shown}"))
            rows.append(Figure(f"{label}: all heard", heard, "s", f"< {goal_heard:g} s" if goal_heard else None,
                               met=(heard < goal_heard) if goal_heard and heard is not None else None,
                               detail="- : a talker was not heard within 60 s" if heard is None else ""))
    record("bringup", rows, goals=["16 components on 3 hosts running in < 3 s and all heard in < 5 s",
                                   "64 components on 4 hosts running in < 10 s"],
           notes=[f"median of {args.repeat} bring-ups each, from `robocore down` (images and trees on the hosts)"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
