"""The rollout's health gate against a fake swarm: ``timeouts.wave`` bounds a whole wave's gate.

No Docker: the swarm adapter's reads are replaced by a swarm whose robot nodes are ready and whose tasks never
(or at once) run, and the gate's clock is a fake one advanced by its own sleeps.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import fleet_world
import pytest
from fleet_world import TWO_ROBOTS, Clock

from robocore.adapters import swarm
from robocore.commands import fleet_gate
from robocore.commands.fleet_gate import FAILED, HEALTHY, Change, Gate
from robocore.commands.fleet_swarm import FleetProject
from robocore.commands.support.context import Options
from robocore.plan import swarm_services as plan

FLEET = TWO_ROBOTS + """\
rollout:
  health: {running: 2}
  timeouts: {robot: 1000, wave: 30}
"""
DIGEST = "@sha256:" + "a" * 64
RELEASE = plan.Release(version="v2", components={"talker": {"amd64": "10.0.0.2:5000/p-talker" + DIGEST}},
                       base={"amd64": "10.0.0.2:5000/p-base" + DIGEST})


@pytest.fixture
def gate(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[Gate, FleetProject, Clock, dict[str, str]]:
    """A gate over a fake swarm where both robots' nodes are ready; ``states[robot]`` is the state of the new task
    of each of that robot's services ("" : none yet)."""
    fleet_project = fleet_world.fleet_project(tmp_path / "p", FLEET)
    project = fleet_project.project
    clock = Clock()
    states = {"r1": "", "r2": ""}
    nodes = [swarm.NodeInfo(id=f"n{r}", hostname=r, labels=plan.node_labels(project.name, r, "main", "amd64"),
                            state="ready", availability="active", addr="") for r in states]

    def tasks(_client: Any, service: str) -> list[swarm.TaskInfo]:
        robot_name = next(r for r in states if f"-{r}-" in service)
        state = states[robot_name]
        image = RELEASE.components["talker"]["amd64"] if "talker" in service else RELEASE.base["amd64"]
        return [swarm.TaskInfo(id=f"t-{service}", node_id=f"n{robot_name}", state=state, desired="running",
                               image=image, created="1", error="", exit_code=None, container="c")] if state else []

    monkeypatch.setattr(fleet_gate, "time", clock)
    monkeypatch.setattr(swarm, "nodes", lambda _client: nodes)
    monkeypatch.setattr(swarm, "tasks", tasks)
    monkeypatch.setattr(swarm, "updating", lambda _client, _name: False)
    the_gate = Gate(object(), fleet_project, RELEASE, {"v2": RELEASE},  # type: ignore[arg-type]
                    Options(project_dir=project.root))
    return the_gate, fleet_project, clock, states


def changes(fleet_project: FleetProject, clock: Clock) -> list[Change]:
    out = []
    for robot in ("r1", "r2"):
        specs = plan.robot_services(fleet_project.project, robot, fleet_project.instances[robot], RELEASE)
        out.append(Change(robot=robot, wave="half", release="v2", specs=specs, before={s.name: set() for s in specs},
                           started=clock.now, deadline=clock.now + fleet_project.fleet.rollout.timeouts.robot))
    return out


def test_a_wave_not_decided_within_its_timeout_fails_like_a_failed_gate(gate: Any) -> None:
    the_gate, fleet_project, clock, states = gate
    states["r1"] = "running"  # r1 passes its gate (no nodes or topics to check); r2's tasks never start
    wave = changes(fleet_project, clock)
    started = clock.now
    the_gate.run(wave, started + fleet_project.fleet.rollout.timeouts.wave)
    assert [c.verdict for c in wave] == [HEALTHY, FAILED]
    assert wave[1].reason == "wave half not decided within 30 s (timeouts.wave)"
    assert 30 <= clock.now - started <= 31  # decided at the wave's deadline, long before the robot's own (1000 s)


def test_a_wave_decided_in_time_is_not_cut_short(gate: Any) -> None:
    the_gate, fleet_project, clock, states = gate
    states.update(r1="running", r2="running")
    wave = changes(fleet_project, clock)
    the_gate.run(wave, clock.now + fleet_project.fleet.rollout.timeouts.wave)
    assert [c.verdict for c in wave] == [HEALTHY, HEALTHY]
    assert clock.now - wave[0].started < 30


def test_without_a_wave_deadline_only_the_robots_own_timeout_applies(gate: Any) -> None:
    the_gate, fleet_project, clock, _ = gate
    wave = changes(fleet_project, clock)
    the_gate.run(wave)
    assert [c.verdict for c in wave] == [FAILED, FAILED]
    assert all(c.reason.startswith("not running after 1000 s") for c in wave), [c.reason for c in wave]


def _ended_probe(gate: Any, monkeypatch: pytest.MonkeyPatch, state: str, code: int, logs: list[str]) -> Change:
    """r1's change with a probe that has ended in ``state`` with exit ``code``; each read of its output through the
    manager gives the next of ``logs`` (the last one from then on)."""
    _, fleet_project, clock, _ = gate
    change = changes(fleet_project, clock)[0]
    change.probe = "p-r1-probe-1"
    probe = swarm.TaskInfo(id="tp", node_id="nr1", state=state, desired="shutdown", image=RELEASE.base["amd64"],
                           created="1", error="", exit_code=code, container="c")
    monkeypatch.setattr(swarm, "tasks", lambda _client, _service: [probe])
    monkeypatch.setattr(swarm, "service_logs", lambda _client, _service: logs.pop(0) if len(logs) > 1 else logs[0])
    monkeypatch.setattr(swarm, "remove_service", lambda _client, _service: None)
    return change


def test_a_probe_whose_output_comes_late_is_read_again(gate: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    the_gate, _, clock, _ = gate
    missing = '{"ok": false, "missing": ["/listener"], "silent": []}'
    change = _ended_probe(gate, monkeypatch, "failed", 1, ["", missing])
    the_gate.probe(change, clock.now)  # exited 1, its output not there yet: read again, its verdict says why
    assert change.verdict is None
    clock.sleep(1)
    the_gate.probe(change, clock.now)
    assert (change.verdict, change.reason) == (FAILED, "nodes missing: /listener")
    change = _ended_probe(gate, monkeypatch, "failed", 1, [""])
    started = clock.now
    while change.verdict is None:  # no output ever: after the wait, the exit code decides
        the_gate.probe(change, clock.now)
        clock.sleep(0.5)
    assert (change.verdict, change.reason) == (FAILED, "the health probe printed no verdict (failed)")
    assert clock.now - started >= fleet_gate.PROBE_LOG_WAIT
    change = _ended_probe(gate, monkeypatch, "complete", 0, ["", "", '{"ok": true}'])
    for _ in range(3):
        the_gate.probe(change, clock.now)
        clock.sleep(1)
    assert change.verdict == HEALTHY


def test_a_probe_that_exited_0_with_no_output_passes_after_the_wait(gate: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    """It exits 0 only when every node was seen and every topic heard: its exit code is the verdict when its output
    never reaches the manager (seen on a robot that had just reconnected)."""
    the_gate, _, clock, _ = gate
    change = _ended_probe(gate, monkeypatch, "complete", 0, [""])
    started = clock.now
    while change.verdict is None:
        the_gate.probe(change, clock.now)
        clock.sleep(0.5)
    assert change.verdict == HEALTHY
    assert clock.now - started >= fleet_gate.PROBE_LOG_WAIT
