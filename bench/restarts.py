"""Heard again after each way a node comes back, beside ``run``'s replace, on one robot in one run.

A one-host ``transport: shm`` robot (the template project: discovery server, talker, listener on this machine as
its one host, the talker and listener sharing its /dev/shm), deployed by ``robocore run`` as a robot runs it
(restart policy ``unless-stopped``). For each way the talker comes back, the seconds from its start (from its
death, for the restart policy) until the listener logs a greeting of the new talker (its count started again):

- ``replace (run)``: the talker's environment changed in robot.yaml and ``robocore run``: a new container, what
  ``dev`` does on every save (the reference: every other way should be as fast);
- ``SIGKILL + start``: the talker killed, then ``docker start``: the same container again;
- ``crash, restart policy``: the talker's process killed from outside Docker (a crash): Docker's restart policy
  starts the container again (its first restart is at once; the rounds are 11 s apart, so it is always the first);
- ``docker restart``: a graceful stop and start.

Every way is timed from the same moment: the new talker process's start, as Docker records it (the container's
``State.StartedAt``), to the wall-clock time the listener's log shows the greeting. Timing from the command
instead would count ``docker start``'s own API round trip (0.1-0.3 s) for one way and not for a ``run`` that
returns after its start. For the crash the figure from the kill is shown too: it adds Docker's own reaction
(noticing the exit, applying the policy).

The ways alternate round after round, so they see the same load; the ratio is each way's median over the
replace's. The machine is shared: read the ratios.

    python bench/restarts.py --project DIR [--rounds 5]

``DIR`` is a built project of the template (``robocore init --defaults --base wheels``, then ``prepare-base``,
``stage`` and ``build``; ``./scripts/demo`` leaves one as ``demo-robot``).
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import signal
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import yaml
from harness import Figure, copy_built_project, record, robocore

from robocore.plan import starts

HEARD = "I heard: hello from talker #"
WAYS = ("replace (run)", "SIGKILL + start", "crash, restart policy", "docker restart")
#: Seconds between rounds: Docker doubles its restart delay for a container that ran less than 10 s.
SPACING = 11.0


def one_host_copy(source: Path, scratch: Path, name: str, *, domain: int, port: int) -> Path:
    """A copy of the built project ``source`` named ``name``: one host, transport shm, one discovery server on
    ``port``, ROS domain ``domain``."""
    root = scratch / name
    copy_built_project(source, root)
    data = yaml.safe_load((root / "robot.yaml").read_text())
    host = data["hosts"][0]["name"]
    data["hosts"] = data["hosts"][:1]
    data["discovery"] = {"servers": [{"host": host, "port": port}], "transport": "shm"}
    data["ros_domain_id"] = domain
    for component in data["components"]:
        component["runs_on"] = host
    (root / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    return root


class Deployed:
    """A project run by ``robocore run`` on this machine: its containers by component, through docker-py."""

    def __init__(self, root: Path, client: Any) -> None:
        self.root, self.client = root, client
        robocore(root, "run", "--quiet")
        self.name = yaml.safe_load((root / "robot.yaml").read_text()).get("name") or root.name

    def container(self, component: str) -> Any:
        [found] = self.client.containers.list(all=True, filters={"label": [f"dev.robocore.project={self.root.name}",
                                                                            f"dev.robocore.component={component}"]})
        return found

    def greetings(self) -> list[int]:
        """The talker numbers the listener logged, oldest first."""
        text = self.container("listener").logs().decode(errors="replace")
        return [int(line.rpartition("#")[2]) for line in text.splitlines()
                if HEARD in line and line.rpartition("#")[2].isdigit()]

    def down(self) -> None:
        robocore(self.root, "down", "--quiet", check=False)


def started_at(container: Any) -> float:
    """The wall-clock time (epoch seconds) Docker recorded for the container's last start."""
    container.reload()
    return starts.docker_epoch(container.attrs["State"]["StartedAt"])


def heard_at(robot: Deployed, mark: int, timeout: float = 30.0) -> float:
    """The wall-clock time at which the listener had logged, after its first ``mark`` greetings, one of a new
    talker (its count started again: not above the last before) (nan: never). A greeting the old talker sent just
    before its end, logged late, is not one: its number is above the last."""
    last = robot.greetings()[mark - 1] if mark else None
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if any(last is None or n <= last for n in robot.greetings()[mark:]):
            return time.time()
        time.sleep(0.02)
    return float("nan")


def come_back(robot: Deployed, way: str) -> tuple[float, float]:
    """The talker brought back ``way``: seconds from its new process's start until heard again, and from the
    request (the command, or for the crash the kill) until heard again."""
    container = robot.container("talker")
    if way == "replace (run)":
        robot_file = robot.root / "robot.yaml"
        data = yaml.safe_load(robot_file.read_text())
        talker = next(c for c in data["components"] if c["name"] == "talker")
        talker["environment"] = {"BENCH_ROUND": str(time.monotonic())}  # a changed spec: run replaces it
        robot_file.write_text(yaml.safe_dump(data, sort_keys=False))
        mark, listener = len(robot.greetings()), robot.container("listener").id
        asked = time.time()
        done = robocore(robot.root, "run")
        if robot.container("listener").id != listener:  # run replaced it too: a new log
            raise SystemExit(f"run replaced the listener as well:\n{done.stdout[-2000:]}")
    elif way == "SIGKILL + start":
        container.kill()
        time.sleep(0.3)
        mark = len(robot.greetings())
        asked = time.time()
        container.start()
    elif way == "crash, restart policy":
        container.reload()
        mark = len(robot.greetings())
        asked = time.time()
        os.kill(container.attrs["State"]["Pid"], signal.SIGKILL)  # not through Docker: the policy applies
    else:
        mark = len(robot.greetings())
        container.restart(timeout=5)
        asked = time.time()  # the stop's seconds are not the way back's
    heard = heard_at(robot, mark)
    return heard - started_at(robot.container("talker")), heard - asked


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--project", type=Path, required=True, help="a built project of the template")
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    import docker

    client = docker.from_env(timeout=300)
    scratch = Path(tempfile.mkdtemp(prefix="robocore-bench-restarts-"))
    robot: Deployed | None = None
    times: dict[str, list[float]] = {}
    asked: dict[str, list[float]] = {}
    try:
        robot = Deployed(one_host_copy(args.project.resolve(), scratch, "bench-restarts", domain=131, port=11931),
                         client)
        if math.isnan(heard_at(robot, 0, 60)):
            raise SystemExit("the listener never heard the talker")
        for n in range(args.rounds):
            for way in WAYS:
                took, since_asked = come_back(robot, way)
                times.setdefault(way, []).append(took)
                asked.setdefault(way, []).append(since_asked)
                print(f"round {n + 1} {way:24} {took:.2f} s from its start, {since_asked:.2f} s from the request",
                      flush=True)
                time.sleep(SPACING)
    finally:
        if robot is not None:
            robot.down()
        shutil.rmtree(scratch, ignore_errors=True)
    reference = statistics.median(times[WAYS[0]])
    figures = []
    print(f"\n{'way':24} {'median s':>9} {'max s':>6} {'x replace':>9} {'from request':>12}")
    for way in WAYS:
        median, worst = statistics.median(times[way]), max(times[way])
        requested = statistics.median(asked[way])
        print(f"{way:24} {median:9.2f} {worst:6.2f} {median / reference:9.2f} {requested:12.2f}")
        figures.append(Figure(f"{way}: heard again after its start (median)", round(median, 2), "s", goal="< 1 s",
                              ratio=round(median / reference, 2), ratio_of="x replace",
                              met=median < 1.0 and worst <= 2.0,
                              detail=f"max {worst:.2f} s; rounds {' '.join(f'{t:.2f}' for t in times[way])}; "
                                     f"from the {'kill' if 'crash' in way else 'command'}: median {requested:.2f} s, "
                                     f"rounds {' '.join(f'{t:.2f}' for t in asked[way])}"))
    record("restarts", figures, goals=["each way < 1 s median, none over 2 s"],
           notes=[f"{args.rounds} rounds per way, the ways alternating, {SPACING:.0f} s apart"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
