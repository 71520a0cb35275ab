"""Bring-up of a whole robot: ``robocore run`` of N components on H robot hosts, to running and to all heard.

A robot of N talkers (the template's talker, one component each, spread round-robin over H simulated robot
hosts, one Fast DDS discovery server on the first) is staged, built, synced and run once (which puts its images
on the hosts); then, ``--repeat`` times:
``robocore down``, a probe process started (a super client of the robot's server, as the pytest plugin's probe
is), and ``robocore run`` timed:

- **running**: from starting ``robocore run`` to its exit (it returns once every container is created and
  started, the discovery server answering first);
- **all heard**: from starting ``robocore run`` until the probe's subscription has matched the publishers of all
  N talkers (each known to it through the discovery server; a talker sends its first greeting as soon as a
  listener matches, so matched is heard within one send; rclpy's message info carries no publisher GID to count
  N identical talkers by their messages).

- **CPU**: the machine's busy CPU-seconds (``/proc/stat``, every process: robocore, Docker, the hosts' daemons,
  the nodes) from starting ``robocore run`` until all heard; divided by the cores, the **CPU floor**: how long
  that work takes with every core busy all the time, the least any ordering of it could take on this machine.

Goals: 16 components on 3 hosts running in < 3 s and all heard in < 5 s; 64 components on 4 hosts running in
< 10 s.

    python bench/bringup.py [--shapes 16x3 64x4] [--repeat 3] [--against CHECKOUT]
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
heard = []
sub = node.create_subscription(String, "chatter", lambda msg: heard.append(time.time()), 100)
print(json.dumps({"ready": time.time()}), flush=True)
deadline = time.time() + float(sys.argv[2])
matched = 0
while time.time() < deadline:
    rclpy.spin_once(node, timeout_sec=0.02)
    now = sub.get_publisher_count()
    if now != matched:
        matched = now
        print(json.dumps({"talkers": matched, "at": time.time()}), flush=True)
    if matched >= expected:
        break
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


def busy_cpu_seconds() -> float:
    """CPU-seconds every core of this machine has spent busy since boot (``/proc/stat``: all but idle and iowait)."""
    with open("/proc/stat") as stat:
        fields = [int(x) for x in stat.readline().split()[1:]]
    idle = fields[3] + fields[4]
    return (sum(fields[:8]) - idle) / os.sysconf("SC_CLK_TCK")


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


def robocore_in(root: Path, *args: str, checkout: Path | None) -> None:
    """``robocore -p ROOT ARGS`` with the robocore package of ``checkout`` (None: the installed one)."""
    env = dict(os.environ)
    if checkout is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(checkout), *filter(None, [env.get("PYTHONPATH")])])
    robocore(root, *args, timeout=600, env=env)


def one_bring_up(root: Path, components: int, env: dict[str, str], checkout: Path | None,
                 timeout: float) -> tuple[float, float | None, float | None]:
    """``robocore down``, then ``robocore run`` timed: (seconds to its exit, seconds until every talker heard, the
    machine's busy CPU-seconds until then)."""
    robocore_in(root, "down", "--quiet", checkout=None)
    probe = subprocess.Popen([sys.executable, "-c", PROBE, str(components), str(timeout)], env=env,
                             stdout=subprocess.PIPE, text=True)
    assert probe.stdout is not None
    json.loads(probe.stdout.readline())  # its node exists: what is heard from now on counts
    start, busy = time.time(), busy_cpu_seconds()
    robocore_in(root, "run", "--quiet", checkout=checkout)
    running = time.time() - start
    last = cpu = None
    for line in probe.stdout:
        event = json.loads(line)
        if event.get("talkers") == components:
            last, cpu = event["at"] - start, busy_cpu_seconds() - busy
    probe.wait(timeout=timeout + 10)
    return running, last, cpu


Run = tuple[float, float | None, float | None]


def heard_within(components: int) -> float:
    """How long the probe waits for every talker: 60 s, and 1 s more per component (64 take over 50 s here)."""
    return 60.0 + components


def summary(runs: list[Run]) -> tuple[float, float | None, float | None, str]:
    """Median running, median all heard (None unless every run heard all), median CPU-seconds until all heard (of
    the runs that heard all; None when none did), and the runs as text."""
    heard_all = [h for _, h, _ in runs if h is not None]
    heard = statistics.median(heard_all) if len(heard_all) == len(runs) else None
    cpus = [c for _, _, c in runs if c is not None]
    cpu = statistics.median(cpus) if cpus else None
    shown = ", ".join(f"{r:.2f}/{'-' if h is None else f'{h:.2f}'}" for r, h, _ in runs)
    return statistics.median(r for r, _, _ in runs), heard, cpu, shown


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--shapes", nargs="+", default=["16x3", "64x4"], help="COMPONENTSxHOSTS")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--against", type=Path, metavar="CHECKOUT",
                        help="another robocore checkout (e.g. a git worktree of an older commit) whose run is timed "
                             "in turn with this one's on the same robot")
    args = parser.parse_args()
    rows: list[Figure] = []
    variants: list[tuple[str, Path | None]] = [("this checkout", None)]
    if args.against:
        head = subprocess.run(["git", "-C", str(args.against), "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, check=False).stdout.strip()
        variants.append((f"against {head or args.against}", args.against.resolve()))
    cores = os.cpu_count() or 1
    print(f"{'robot':<28}{'robocore':<22}{'running s':>10}{'all heard s':>13}{'CPU s':>8}{'floor s':>9}"
          "   runs (running/all heard)")
    with tempfile.TemporaryDirectory(prefix="robocore-bench-bringup-") as scratch:
        for shape in args.shapes:
            components, hosts = (int(x) for x in shape.split("x"))
            label = f"{components} components on {hosts} hosts"
            runs: dict[str, list[Run]] = {name: [] for name, _ in variants}
            with RobotFleet(hosts, tag=f"bu{components}") as fleet:
                root = make_project(Path(scratch), components, fleet)
                env = probe_env(root)
                for _ in range(args.repeat):  # in turn, so that both see the same load
                    for name, checkout in variants:
                        runs[name].append(one_bring_up(root, components, env, checkout, heard_within(components)))
                robocore_in(root, "down", "--quiet", checkout=None)
            goal_running, goal_heard = GOALS.get(shape, (None, None))
            mine = summary(runs["this checkout"])[0]
            for name, _ in variants:
                running, heard, cpu, shown = summary(runs[name])
                floor = None if cpu is None else cpu / cores
                print(f"{label:<28}{name:<22}{running:>10.2f}{'-' if heard is None else f'{heard:.2f}':>13}"
                      f"{'-' if cpu is None else f'{cpu:.1f}':>8}{'-' if floor is None else f'{floor:.2f}':>9}"
                      f"   {shown}")
                ratio = running / mine if name != "this checkout" else None
                rows.append(Figure(f"{label}, {name}: running", running, "s",
                                   f"< {goal_running:g} s" if goal_running else None,
                                   ratio=ratio, ratio_of="x this checkout" if ratio else "",
                                   met=running < goal_running if goal_running else None,
                                   detail=f"median of {len(runs[name])}; runs (running/all heard): {shown}"))
                rows.append(Figure(f"{label}, {name}: all heard", heard, "s",
                                   f"< {goal_heard:g} s" if goal_heard else None,
                                   met=(heard < goal_heard) if goal_heard and heard is not None else None,
                                   detail="" if heard is not None
                                   else f"- : a talker was not heard within {heard_within(components):g} s"))
                rows.append(Figure(f"{label}, {name}: busy CPU until all heard", cpu, "CPU-s",
                                   detail="" if cpu is None else f"{cpu / components:.2f} CPU-s per component"))
                rows.append(Figure(f"{label}, {name}: CPU floor (that CPU on {cores} cores)", floor, "s",
                                   f"< {goal_heard:g} s" if goal_heard else None,  # the floor of all heard
                                   met=floor < goal_heard if goal_heard and floor is not None else None,
                                   detail="the least any ordering of that work could take here"))
    record("bringup", rows, goals=["16 components on 3 hosts running in < 3 s and all heard in < 5 s",
                                   "64 components on 4 hosts running in < 10 s"],
           notes=[f"median of {args.repeat} bring-ups each, from `robocore down` (images and trees on the hosts)"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
