"""Recovery figures of a two-host robot under faults, side by side in one run, through the ``robot`` fixture's
machinery (``robocore.testing.bring_up`` and ``robot.faults``).

The robot is the template project (``robocore init --defaults --base wheels``, built once first, or
``--project DIR`` of a built one) on two hosts: the talker (2 Hz) on ``main``, the listener on ``arm``;
the test process's node (the probe) counts the talker's sequence numbers. Figures:

1. two servers (one per host): messages lost while server 0, then server 1, is killed for 8 s (goal 0);
   a node started on ``main`` during each outage, time until the probe hears it (goal < 2 s);
2. one server (on ``main``): a node started right after the server's restart, time until heard (goal < 5 s);
3. two servers: host ``main`` cut off for 3 s, reconnection to the next message (goal < 5 s);
4. two servers: host ``main`` power-cut and booted, boot to the talker heard again.

Each figure is the median of ``--repeat`` runs (default 3). The machine is shared: read ratios, not seconds.
Every run of a scenario is a process of its own (this script again, ``--scenario``, which prints its figures
as one JSON line): Fast DDS reads its XML profiles once per process, so a second ``bring_up`` in one process
kept the first robot's discovery servers and heard nothing.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml
from harness import Figure, copy_built_project, record

PUBLISH = """
import sys, time
start = time.time()
import rclpy
from std_msgs.msg import String
rclpy.init()
node = rclpy.create_node("late_" + sys.argv[1])
pub = node.create_publisher(String, "chatter", 10)
for i in range(1200):
    pub.publish(String(data=f"late {sys.argv[1]} {start} {i}"))
    time.sleep(0.05)
"""


def make_project(scratch: Path, source: Path | None, servers: list[str]) -> Path:
    """A copy of the template project with talker on main, listener on arm, discovery servers on ``servers``."""
    root = scratch / f"faults-bench-{len(servers)}"
    if source is None:
        source = scratch / "template"
        if not source.exists():
            subprocess.run([sys.executable, "-m", "robocore", "init", str(source), "--defaults", "--base", "wheels"],
                           check=True, capture_output=True)
    copy_built_project(source, root)
    data = yaml.safe_load((root / "robot.yaml").read_text())
    first = data["hosts"][0]
    first.update(name="main", ip="192.0.2.9", user="root")
    data["hosts"] = [first, {**first, "name": "arm", "ip": "192.0.2.10"}]
    data["components"][0]["runs_on"], data["components"][1]["runs_on"] = "main", "arm"
    data["discovery"] = {"servers": [{"host": h, "port": 11811} for h in servers]}
    (root / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    return root


class Probe:
    """The probe's view of the talker: arrival time and sequence number of every /chatter message."""

    def __init__(self, robot: Any) -> None:
        from std_msgs.msg import String

        self.robot = robot
        self.seen: list[tuple[float, int]] = []
        self.late: dict[str, float] = {}
        robot.graph.node.create_subscription(String, "/chatter", self._chatter, 100)

    def _chatter(self, msg: Any) -> None:
        if msg.data.startswith("late "):
            _, tag, start, _ = msg.data.split()
            self.late.setdefault(tag, time.time() - float(start))
        else:
            self.seen.append((time.monotonic(), int(msg.data.rpartition("#")[2])))

    def first_after(self, start: float, timeout: float = 40) -> float | None:
        """Seconds from ``start`` (monotonic) to the next talker message, or None."""
        while time.monotonic() < start + timeout:
            self.robot.graph.spin(0.05)
            later = [t for t, _ in self.seen if t > start]
            if later:
                return later[0] - start
        return None

    def late_node_heard(self, tag: str, timeout: float = 50) -> float | None:
        """Start a new node on host main publishing on /chatter; seconds from its process's start to the probe
        hearing it (on /chatter, which the probe already subscribes to)."""
        threading.Thread(target=self.robot.exec, args=("talker", ["python3", "-c", PUBLISH, tag]), daemon=True).start()
        deadline = time.monotonic() + timeout
        while tag not in self.late and time.monotonic() < deadline:
            self.robot.graph.spin(0.05)
        return self.late.get(tag)


def lost_across(probe: Probe, action: Callable[[], None], seconds: float) -> int:
    """Talker messages missing at the probe from just before ``action`` to ``seconds`` after it."""
    probe.robot.graph.spin(1.0)
    mark = len(probe.seen)
    action()
    probe.robot.graph.spin(seconds)
    numbers = [n for _, n in probe.seen[mark - 1:]]
    return sum(b - a - 1 for a, b in itertools.pairwise(numbers) if b > a)


def two_servers(robot: Any, probe: Probe, figures: dict[str, list[float]]) -> None:
    for index in (0, 1):
        service = f"discovery-{index}"
        late: list[float | None] = []

        def outage(service: str = service, late: list[float | None] = late, index: int = index) -> None:
            robot.kill(service)
            late.append(probe.late_node_heard(f"s{index}_{len(figures['lost_s0'])}"))

        figures[f"lost_s{index}"].append(lost_across(probe, outage, 8.0))
        figures[f"late_during_s{index}_outage"].append(late[0] if late[0] is not None else float("nan"))
        robot.start(service)
        robot.graph.spin(15.0)  # its restart hold, then serving again
    robot.faults.cut_off("main")
    robot.graph.spin(3.0)
    robot.faults.reconnect("main")
    figures["reconnect_to_message"].append(probe.first_after(time.monotonic()) or float("nan"))
    robot.faults.power_cut("main")
    robot.graph.spin(2.0)
    booted = time.monotonic()
    robot.faults.boot("main")
    figures["boot_to_heard"].append(probe.first_after(booted) or float("nan"))


def one_server(robot: Any, probe: Probe, figures: dict[str, list[float]]) -> None:
    robot.graph.spin(3.0)
    robot.restart("discovery-0")
    figures["late_after_single_restart"].append(probe.late_node_heard(f"r{len(figures['lost_s0'])}") or float("nan"))


SCENARIOS: dict[str, tuple[int, Callable[[Any, Probe, dict[str, list[float]]], None]]] = {
    "two_servers": (2, two_servers), "one_server": (1, one_server)}
FIGURES = ("lost_s0", "late_during_s0_outage", "lost_s1", "late_during_s1_outage", "late_after_single_restart",
           "reconnect_to_message", "boot_to_heard")
GOALS = {"lost_s0": "0 (today 0)", "lost_s1": "0 (today 0)", "late_during_s0_outage": "< 2 s (today 4.8 s)",
         "late_during_s1_outage": "< 2 s (today 4.8 s)", "late_after_single_restart": "< 5 s (today 12.3 s)",
         "reconnect_to_message": "< 5 s", "boot_to_heard": "-"}
#: The line a scenario process prints its figures on.
MARK = "FAULTS-BENCH-FIGURES "


def run_scenario(name: str, project: Path) -> int:
    """One bring-up of ``project``, one run of scenario ``name``; its figures as one JSON line on stdout."""
    from robocore.testing import bring_up

    figures: dict[str, list[float]] = {k: [] for k in FIGURES}
    robot = bring_up(project)
    try:
        probe = Probe(robot)
        if probe.first_after(time.monotonic()) is None:
            print("the probe never heard the talker", file=sys.stderr)
        SCENARIOS[name][1](robot, probe, figures)
    finally:
        robot.close()
    print(MARK + json.dumps({k: v for k, v in figures.items() if v}), flush=True)
    return 0


def scenario_process(name: str, project: Path) -> dict[str, list[float]]:
    """``name`` run by this script in a new process; its figures (none, with its output's tail, if it failed)."""
    proc = subprocess.run([sys.executable, __file__, "--scenario", name, "--project", str(project)],
                          capture_output=True, text=True, timeout=900)
    for line in proc.stdout.splitlines():
        if line.startswith(MARK):
            return {k: [float(x) for x in v] for k, v in json.loads(line[len(MARK):]).items()}
    print(f"scenario {name} failed (exit {proc.returncode}):\n{proc.stdout[-1500:]}\n{proc.stderr[-3000:]}",
          file=sys.stderr)
    return {}


def verdict(name: str, heard: list[float]) -> bool | None:
    """Whether the median of ``heard`` meets the figure's goal (None: it has none)."""
    limit = {"lost_s0": 0.5, "lost_s1": 0.5, "late_during_s0_outage": 2.0, "late_during_s1_outage": 2.0,
             "late_after_single_restart": 5.0, "reconnect_to_message": 5.0}.get(name)
    return None if limit is None else statistics.median(heard) < limit


def show(value: float, unit: str) -> str:
    return "nan" if math.isnan(value) else f"{value:.1f}" if unit else f"{value:.0f}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--project", type=Path, help="a built template project (default: a new one)")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--scenario", choices=sorted(SCENARIOS), help=argparse.SUPPRESS)  # one run, in this process
    args = parser.parse_args()
    if args.scenario:
        return run_scenario(args.scenario, args.project)

    figures: dict[str, list[float]] = {k: [] for k in FIGURES}
    with tempfile.TemporaryDirectory(prefix="robocore-bench-faults-") as scratch:
        projects = {name: make_project(Path(scratch), args.project, ["main", "arm"][:count])
                    for name, (count, _) in SCENARIOS.items()}
        for _ in range(args.repeat):
            for name in SCENARIOS:
                for key, values in scenario_process(name, projects[name]).items():
                    figures[key] += values
    print(f"\n| figure (median of {args.repeat} runs, one process each; shared 2-core machine) | value | runs | goal |")
    print("|---|---|---|---|")
    rows = []
    for name, values in figures.items():
        unit = "" if name.startswith("lost") else " s"
        heard = [v for v in values if not math.isnan(v)]  # nan: not heard within the wait
        median = show(statistics.median(heard), unit) + unit if heard else "-"
        runs = ", ".join(show(v, unit) for v in values)
        print(f"| {name} | {median} | {runs} | {GOALS[name]} |")
        rows.append(Figure(name, statistics.median(heard) if heard else None, unit.strip() or "messages",
                           GOALS[name] if GOALS[name] != "-" else None, met=verdict(name, heard) if heard else None,
                           detail=f"runs: {runs}"))
    record("faults", rows, goals=["no message lost while one of two servers is down", "a node started during an "
                                  "outage heard in < 2 s", "a node started after a single server's restart heard "
                                  "in < 5 s", "reconnection to the next message < 5 s"],
           notes=[f"median of {args.repeat} runs, one process each (nan: not heard within the wait)"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
