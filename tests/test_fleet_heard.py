"""The gate's heard bound and what it says while it waits, against a fake swarm and a fake clock.

A robot whose containers run only after a long first pull, then whose talker runs but is never heard: the probe is
given ``timeouts.heard`` counted from the moment the containers run (not the robot timeout's rest), so the robot is
decided on that shorter bound; meanwhile the gate says, about every 10 s, what it waits for.
"""

from __future__ import annotations

import json
from pathlib import Path

import fleet_world
import pytest
from fleet_world import Clock

from robocore.adapters import swarm
from robocore.commands import fleet_gate
from robocore.commands.fleet_gate import FAILED, Change, Gate
from robocore.commands.fleet_swarm import FleetProject
from robocore.commands.support.context import Options
from robocore.plan import swarm_services as plan

FLEET = """\
manager: {ip: 10.0.0.2}
registry: 10.0.0.2:5000
robots:
  - {name: r1, hosts: {main: {ip: 10.1.1.1}}}
rollout:
  health: {running: 5, nodes: [/talker], heard: [/chatter]}
  timeouts: {robot: 300%s}
"""
DIGEST = "@sha256:" + "b" * 64
RELEASE = plan.Release(version="v5", components={"talker": {"amd64": "10.0.0.2:5000/p-talker" + DIGEST}},
                       base={"amd64": "10.0.0.2:5000/p-base" + DIGEST})
#: Seconds the fake robot's first pull takes: its containers run only after it.
PULL = 50.0


class SilentRobot:
    """A fake swarm with one robot whose tasks run after :data:`PULL` seconds and whose probe never hears /chatter:
    the probe prints a progress line every 5 s and its failed verdict once its ``--timeout`` is over."""

    def __init__(self, clock: Clock) -> None:
        self.clock = clock
        self.began = clock.now
        self.probe_timeout: float | None = None
        self.probe_started = 0.0

    def tasks(self, _client: object, service: str) -> list[swarm.TaskInfo]:
        if "-probe-" in service:
            ended = self.probe_timeout is not None and self.clock.now >= self.probe_started + self.probe_timeout
            return [swarm.TaskInfo(id="tp", node_id="n1", state="failed" if ended else "running",
                                   desired="shutdown" if ended else "running", image=RELEASE.base["amd64"],
                                   created="1", error="", exit_code=1 if ended else None, container="c")]
        image = RELEASE.components["talker"]["amd64"] if "talker" in service else RELEASE.base["amd64"]
        if self.clock.now - self.began < PULL:
            return [swarm.TaskInfo(id=f"t-{service}", node_id="n1", state="preparing", desired="running",
                                   image=image, created="1", error="", exit_code=None, container="")]
        return [swarm.TaskInfo(id=f"t-{service}", node_id="n1", state="running", desired="running", image=image,
                               created="1", error="", exit_code=None, container="c")]

    def apply_service(self, _client: object, spec: plan.ServiceSpec, _ids: object) -> str:
        assert spec.args is not None
        self.probe_timeout = float(spec.args[list(spec.args).index("--timeout") + 1])
        self.probe_started = self.clock.now
        return "probe-id"

    def service_logs(self, _client: object, _service: str) -> str:
        waited = int((self.clock.now - self.probe_started) // 5)
        lines = [json.dumps({"waiting": True, "missing": [], "silent": ["/chatter"]})] * waited
        if self.probe_timeout is not None and self.clock.now >= self.probe_started + self.probe_timeout:
            lines.append(json.dumps({"ok": False, "missing": [], "silent": ["/chatter"]}))
        return "\n".join(f"p.1.x@robot | {line}" for line in lines)


def world(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, heard: str) -> tuple[Gate, Change, Clock, SilentRobot]:
    fleet_project: FleetProject = fleet_world.fleet_project(tmp_path / "p", FLEET % heard)
    project = fleet_project.project
    clock = Clock()
    robot = SilentRobot(clock)
    node = swarm.NodeInfo(id="n1", hostname="r1", labels=plan.node_labels(project.name, "r1", "main", "amd64"),
                          state="ready", availability="active", addr="")
    monkeypatch.setattr(fleet_gate, "time", clock)
    monkeypatch.setattr(swarm, "nodes", lambda _client: [node])
    monkeypatch.setattr(swarm, "updating", lambda _client, _name: False)
    monkeypatch.setattr(swarm, "ensure_configs", lambda _client, _configs: {})
    monkeypatch.setattr(swarm, "remove_service", lambda _client, _name: None)
    for name in ("tasks", "apply_service", "service_logs"):
        monkeypatch.setattr(swarm, name, getattr(robot, name))
    gate = Gate(object(), fleet_project, RELEASE, {"v5": RELEASE}, Options(project_dir=project.root))  # type: ignore[arg-type]
    specs = plan.robot_services(project, "r1", fleet_project.instances["r1"], RELEASE)
    change = Change(robot="r1", wave="canary", release="v5", specs=specs, before={s.name: set() for s in specs},
                    started=clock.now, deadline=clock.now + fleet_project.fleet.rollout.timeouts.robot)
    return gate, change, clock, robot


def test_a_robot_that_runs_unheard_is_decided_on_the_heard_bound_from_when_it_runs(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    gate, change, clock, robot = world(tmp_path, monkeypatch, ", heard: 20")
    gate.run([change])
    assert (change.verdict, change.reason) == (FAILED, "not heard: /chatter")
    # the probe had what was left of 20 s after the containers had run 5 s (health.running), not the robot
    # timeout's rest (300 s less the pull)
    assert robot.probe_timeout is not None and 14 <= robot.probe_timeout <= 15, robot.probe_timeout
    assert PULL + 20 <= clock.now - change.started <= PULL + 22  # counted from the run, not from the change


def test_without_a_heard_key_the_bound_is_30_s_and_the_robot_timeout_still_caps_it(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    gate, change, _, robot = world(tmp_path, monkeypatch, "")
    gate.run([change])
    assert change.verdict == FAILED and robot.probe_timeout is not None and 24 <= robot.probe_timeout <= 25
    assert gate.timeouts.heard == 30
    gate, change, _, robot = world(tmp_path, monkeypatch, ", heard: 600")  # longer than the robot's
    gate.run([change])
    assert change.verdict == FAILED and robot.probe_timeout is not None
    assert robot.probe_timeout <= change.deadline - robot.probe_started  # the robot timeout's rest


def test_while_it_waits_the_gate_says_what_for_every_10_s(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    gate, change, clock, _ = world(tmp_path, monkeypatch, ", heard: 30")
    gate.run([change])
    said = [line for line in capsys.readouterr().err.splitlines() if line.startswith("  r1: ")]
    took = clock.now - change.started
    assert took // fleet_gate.PROGRESS - 1 <= len(said) <= took // fleet_gate.PROGRESS + 1, said
    assert said[0] == ("  r1: waits for its containers to run: discovery-0 preparing, talker preparing (10 s of 300 s, "
                        "timeouts.robot)"), said
    assert any(line.startswith("  r1: every container running for ") and line.endswith("of 5 s (health.running)")
               for line in said) or PULL % fleet_gate.PROGRESS == 0, said
    graph = [line for line in said if "its graph" in line]
    assert graph and all(line.startswith("  r1: its graph: not yet heard: /chatter (") and
                         line.endswith("of 30 s, timeouts.heard)") for line in graph), said
    # the negative control: a robot decided at once says nothing
    capsys.readouterr()
    change.verdict, change.said = FAILED, 0.0
    gate.say([change])
    assert capsys.readouterr().err == ""


def test_progress_lines_are_never_taken_for_the_verdict() -> None:
    waiting = '{"waiting": true, "missing": ["/talker"], "silent": []}'
    assert plan.probe_verdict(f"t@n | {waiting}\n") is None  # a probe stopped while it waited: no verdict
    assert plan.probe_progress(f"t@n | {waiting}\n") == {"missing": ["/talker"], "silent": []}
    done = '{"ok": true, "missing": [], "silent": []}'
    assert plan.probe_verdict(f"{waiting}\n{done}\n{waiting}\n") == {"ok": True, "missing": [], "silent": []}
    assert plan.probe_progress(done) is None
