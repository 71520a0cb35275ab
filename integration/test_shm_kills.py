"""A component back in place on a one-host ``transport: shm`` robot: SIGKILLed 20 times in a row, crashed and
restarted by its restart policy, started again after a SIGKILL (by the ``robot`` fixture and by ``robocore run``),
restarted gracefully.

The demo project's talker and listener share their host's IPC namespace (the run's host container), so
Fast DDS moves their data through segments in that host's /dev/shm. A SIGKILLed process cannot remove
its segments and port files. After every restart the listener must hear the talker again, and what the
dead processes left in /dev/shm must not pile up (the test counts Fast DDS's files there after every
cycle; Fast DDS 2.14 removes a dead process's files later, so robocore cleans nothing itself). The
negative control: while the talker is dead the listener's count does not rise, so "heard again" is a
real change, not old log lines.

Each way of coming back in place is also timed, five rounds each, from the new talker
process's start as Docker records it (``State.StartedAt``) to the listener's first greeting of it as Docker's log
timestamps record it: both clocks are the daemon's, so the test process's own scheduling on a busy machine adds
nothing. Each way's median must be within 2 s (``run``'s replace, the reference, is 0.75 s median on a quiet
2-core machine: see ``bench/restarts.py``, which measures the same ways beside it).

One bring-up for the module: the tests share the robot.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from deploy_helpers import copy_project, project_containers, remove_project_containers, remove_test_runs
from ways_back import HEARD, POLICY_SPACING, Pair

pytestmark = pytest.mark.docker

CYCLES = 20
#: Rounds of each way of coming back in place, and the bound on their median (seconds from start to heard).
ROUNDS = 5
BOUND = 2.0


@pytest.fixture(scope="module")
def robot(demo_project: Path, tmp_path_factory: pytest.TempPathFactory, docker_client: Any) -> Iterator[Any]:
    """A copy of the demo project with ``transport: shm``, brought up once for the module (no probe node)."""
    from robocore.testing import bring_up

    name = f"robocore-it-shm-kills-{int(time.time() * 1000) % 100000}"
    root = copy_project(demo_project, tmp_path_factory.mktemp("shm-kills"), name, transport="shm")
    run = bring_up(root, servers=True, graph=False)
    try:
        assert wait_heard_after(run, 0, 30), "the listener never heard the talker"
        yield run
    finally:
        run.close()
        remove_test_runs(docker_client, name)
        remove_project_containers(docker_client, name)


def heard(robot: Any) -> list[int]:
    """The talker numbers in the listener's log, oldest first."""
    return [int(line.rpartition("#")[2]) for line in robot.logs("listener").splitlines()
            if HEARD in line and line.rpartition("#")[2].isdigit()]


def shm_files(robot: Any) -> list[str]:
    """The Fast DDS files in the talker's host's /dev/shm (seen from the listener, which shares it)."""
    code, out = robot.exec("listener", ["ls", "-1", "/dev/shm"])
    assert code == 0, out
    return sorted(name for name in out.split() if "fastrtps" in name or "fastdds" in name)


def wait_heard_after(robot: Any, mark: int, timeout: float) -> list[int]:
    """What the listener heard after its first ``mark`` messages, once there is something (else [])."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        new = heard(robot)[mark:]
        if new:
            return new
        time.sleep(0.1)
    return []


def dead(robot: Any, component: str) -> bool:
    container = robot.client.containers.get(robot.specs[component].name)
    return bool(container.status == "exited" and container.attrs["State"]["ExitCode"] == 137)


def test_a_talker_sigkilled_20_times_is_heard_again_after_every_restart(robot: Any) -> None:
    files_at_start = shm_files(robot)
    assert any(name.startswith("fastrtps_port") for name in files_at_start), (
        f"no Fast DDS shared-memory port in the host's /dev/shm: {files_at_start}")

    # negative control: with the talker dead, nothing new is heard, so the check below can fail
    robot.kill("talker")
    time.sleep(0.5)
    mark = len(heard(robot))
    assert wait_heard_after(robot, mark, 3.0) == [], "the listener heard a SIGKILLed talker"
    robot.start("talker")
    assert wait_heard_after(robot, mark, 30), "the talker was not heard after its first restart"

    seconds: list[float] = []
    files: list[int] = []
    for cycle in range(CYCLES):
        robot.kill("talker")
        time.sleep(0.3)
        assert dead(robot, "talker"), f"cycle {cycle}: the talker did not die of SIGKILL"
        mark = len(heard(robot))
        started = time.monotonic()
        robot.start("talker")
        new = wait_heard_after(robot, mark, 30)
        assert new, (f"cycle {cycle + 1}/{CYCLES}: the listener did not hear the restarted talker within 30 s; "
                     f"/dev/shm: {shm_files(robot)}; heard {len(seconds)}/{CYCLES} before")
        assert min(new) <= 20, f"cycle {cycle + 1}: the talker's count did not restart: {new}"
        seconds.append(time.monotonic() - started)
        files.append(len(shm_files(robot)))
    left = shm_files(robot)
    print(f"FIGURE heard_again {len(seconds)}/{CYCLES}; start to heard s: median {statistics.median(seconds):.2f}, "
          f"max {max(seconds):.2f}; Fast DDS files in /dev/shm: {len(files_at_start)} at start, "
          f"after each cycle {files}; at the end, not there at start: {sorted(set(left) - set(files_at_start))}")
    # what the 21 dead talkers left behind does not pile up. Fast DDS removes a dead process's files later (the
    # count after each cycle rises and falls), so how many are left at one moment depends on the cycles' pace:
    # 23-25 when a restart was heard after 1.75 s, 23-31 at 0.7 s. Kept files would add 2 per cycle (61 at the end);
    # the bound is six dead processes' worth, at every cycle and at the end.
    bound = len(files_at_start) + 12
    assert max(files) <= bound, (files_at_start, files)
    assert len(left) <= bound, (files_at_start, left)


# --------------------------------------------------------------------------- each way back in place, timed


@dataclass(frozen=True)
class Deployed:
    """The project ``robocore run`` deployed, and its talker and listener."""

    root: Path
    pair: Pair


@pytest.fixture(scope="module")
def deployed(demo_project: Path, tmp_path_factory: pytest.TempPathFactory, docker_client: Any,
             run_robocore: Any) -> Iterator[Deployed]:
    """A copy of the demo project with ``transport: shm`` deployed by ``robocore run`` as on a robot (restart
    policy ``unless-stopped``; the ``robot`` fixture's containers never restart on their own)."""
    name = f"robocore-it-shm-policy-{int(time.time() * 1000) % 100000}"
    root = copy_project(demo_project, tmp_path_factory.mktemp("shm-policy"), name, transport="shm")
    try:
        run_robocore(root, "run", "--quiet")
        pair = Pair(docker_client, f"{name}-talker", f"{name}-listener")
        pair.wait_heard()
        yield Deployed(root, pair)
    finally:
        remove_project_containers(docker_client, name)


@pytest.mark.quiet
def test_a_crashed_talker_restarted_by_its_policy_is_heard_within_2_s(deployed: Deployed) -> None:
    """The talker's process killed from outside Docker (a crash): Docker's restart policy starts it again."""
    pair = deployed.pair
    restarts = pair.talker().attrs["RestartCount"]
    seconds = pair.timed_rounds(pair.crash, "crash, restart policy", ROUNDS, spacing=POLICY_SPACING)
    assert pair.talker().attrs["RestartCount"] == restarts + ROUNDS, "the restart policy did not restart it"
    assert statistics.median(seconds) < BOUND, seconds


@pytest.mark.quiet
def test_a_talker_sigkilled_then_started_by_run_in_place_is_heard_within_2_s(deployed: Deployed,
                                                                             run_robocore: Any) -> None:
    """``docker kill`` (which its restart policy leaves dead), then ``robocore run``: it starts the same container
    again, its own way back in place (neither replaced nor re-created)."""
    pair = deployed.pair
    container_id = pair.talker().id
    others = {c.name: c.id for c in project_containers(pair.client, deployed.root.name) if c.id != container_id}

    def kill_then_run() -> None:
        pair.talker().kill()
        time.sleep(0.3)
        assert pair.talker().status == "exited", "its restart policy started it: run would have nothing to do"
        run_robocore(deployed.root, "run", "--quiet")
        now = {c.name: c.id for c in project_containers(pair.client, deployed.root.name) if c.id != container_id}
        assert now == others, f"run replaced what was running (before, after): {others}, {now}"

    seconds = pair.timed_rounds(kill_then_run, "SIGKILL, then run", ROUNDS)
    assert pair.talker().id == container_id, "run replaced the talker instead of starting it in place"
    assert statistics.median(seconds) < BOUND, seconds


@pytest.mark.quiet
def test_a_talker_started_again_after_a_sigkill_is_heard_within_2_s(robot: Any) -> None:
    """The ``robot`` fixture's ``kill`` then ``start``: the same container in place."""
    pair = Pair(robot.client, robot.specs["talker"].name, robot.specs["listener"].name)

    def kill_and_start() -> None:
        robot.kill("talker")
        time.sleep(0.3)
        robot.start("talker")

    seconds = pair.timed_rounds(kill_and_start, "SIGKILL + start", ROUNDS)
    assert statistics.median(seconds) < BOUND, seconds


@pytest.mark.quiet
def test_a_talker_restarted_gracefully_is_heard_within_2_s(robot: Any) -> None:
    """The ``robot`` fixture's ``restart``: SIGTERM, the node's clean shutdown, a start in place."""
    pair = Pair(robot.client, robot.specs["talker"].name, robot.specs["listener"].name)
    seconds = pair.timed_rounds(lambda: robot.restart("talker"), "restart", ROUNDS)
    assert statistics.median(seconds) < BOUND, seconds
