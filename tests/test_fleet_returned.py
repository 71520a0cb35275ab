"""A robot that missed a rollout while offline is gated once ``fleet status`` sees it back on its target.

From a fake manager's look: which rows count as back and not gated since (``pending``, online, running the
target), and ``fleet status`` gating exactly those, changing nothing of them but their health labels.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import fleet_world
import pytest
from fleet_world import TWO_ROBOTS

from robocore.adapters import swarm
from robocore.commands import fleet_returned, fleet_status
from robocore.commands.fleet_gate import HEALTHY, PENDING, Change, Gate
from robocore.commands.fleet_status import Observed, status_rows
from robocore.commands.fleet_swarm import FleetProject
from robocore.commands.support.context import Options
from robocore.plan import naming
from robocore.plan import swarm_services as plan

FLEET = TWO_ROBOTS + """\
  - {name: r3, hosts: {main: {ip: 10.1.3.1}}}
  - {name: r4, hosts: {main: {ip: 10.1.4.1}}}
"""
V1, V2 = "10.0.0.2:5000/p-talker@sha256:" + "1" * 64, "10.0.0.2:5000/p-talker@sha256:" + "2" * 64
BASE = "10.0.0.2:5000/p-base@sha256:" + "0" * 64


def look(project: str) -> Observed:
    """r1: healthy on v2. r2: pending, back online, running its target v2 (the one to gate). r3: pending, still
    offline. r4: pending, online, but still on v1 (Swarm has not converged it yet)."""
    def service(robot: str, health: str, part: str = "talker") -> swarm.ServiceInfo:
        image, before = (V2, V1) if part == "talker" else (BASE, BASE)
        labels = {naming.LABEL_PROJECT: project, plan.LABEL_ROBOT: robot, naming.LABEL_COMPONENT: part,
                  naming.LABEL_ROLE: naming.ROLE_COMPONENT if part == "talker" else naming.ROLE_DISCOVERY,
                  plan.LABEL_RELEASE: "v2", plan.LABEL_IMAGE: image, plan.LABEL_PREVIOUS: "v1",
                  plan.LABEL_PREVIOUS_IMAGE: before, plan.LABEL_HEALTH: health}
        return swarm.ServiceInfo(id=robot, name=f"{project}-{robot}-{part}", labels=labels, image=image, version=1,
                                 attrs={})

    def task(image: str) -> list[swarm.TaskInfo]:
        return [swarm.TaskInfo(id="t", node_id="n", state="running", desired="running", image=image, created="1",
                               error="", exit_code=None, container="c")]

    services = [service(robot, health, part) for robot, health in (("r1", HEALTHY), ("r2", PENDING),
                                                                   ("r3", PENDING), ("r4", PENDING))
                for part in ("discovery-0", "talker")]
    nodes = {r: [swarm.NodeInfo(id=f"n{r}", hostname=r, labels=plan.node_labels(project, r, "main", "amd64"),
                                state="ready", availability="active", addr="")] for r in ("r1", "r2", "r4")}
    tasks = {s.name: task(BASE if s.name.endswith("-discovery-0") else V1 if "-r4-" in s.name else V2)
             for s in services}
    return Observed(by_robot=nodes, services=services, tasks=tasks)


@pytest.fixture
def fleet_project(tmp_path: Path) -> FleetProject:
    return fleet_world.fleet_project(tmp_path / "p", FLEET)


def test_only_a_pending_robot_back_online_on_its_target_is_to_be_gated(fleet_project: FleetProject) -> None:
    rows = status_rows(fleet_project, look(fleet_project.name))
    assert [(r.robot, r.health, r.state) for r in rows] == [
        ("r1", HEALTHY, "online"), ("r2", PENDING, "online"), ("r3", PENDING, "offline"),
        ("r4", PENDING, "online, pending")]
    assert fleet_returned.back_and_ungated([(r.robot, r.health, r.state) for r in rows]) == ["r2"]


def test_fleet_status_gates_the_robot_back_and_shows_its_verdict(fleet_project: FleetProject,
                                                                  monkeypatch: pytest.MonkeyPatch,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    seen = look(fleet_project.name)
    labelled: dict[str, dict[str, str]] = {}
    gated: list[Change] = []

    def observe(_fleet: FleetProject) -> Observed:  # the second look sees the labels the gate wrote
        for service in seen.services:
            service.labels.update(labelled.get(service.name, {}))
        return seen

    def run(_gate: Gate, changes: list[Change], *_: Any) -> None:
        for change in changes:
            change.verdict = HEALTHY
        gated.extend(changes)

    class Client:
        def close(self) -> None:
            pass

    monkeypatch.setattr(fleet_status, "load", lambda _options: fleet_project)
    monkeypatch.setattr(fleet_status, "observe", observe)
    monkeypatch.setattr(fleet_returned, "manager_client", lambda _fleet: Client())
    monkeypatch.setattr(swarm, "services", lambda _client, _label: seen.services)
    monkeypatch.setattr(swarm, "tasks", lambda _client, name: seen.tasks.get(name, []))
    monkeypatch.setattr(swarm, "set_labels", lambda _client, name, labels: labelled.setdefault(name, {}).update(labels))
    monkeypatch.setattr(Gate, "run", run)
    rows = fleet_status.status(Options(project_dir=fleet_project.project.root))
    assert [(c.robot, c.release, [s.image for s in c.specs if s.component == "talker"]) for c in gated] == \
        [("r2", "v2", [V2])]  # gated on what it runs, nothing else
    assert sorted(labelled) == [f"{fleet_project.name}-r2-{part}" for part in ("discovery-0", "talker")]
    assert [(r.robot, r.health) for r in rows] == [("r1", HEALTHY), ("r2", HEALTHY), ("r3", PENDING), ("r4", PENDING)]
    assert "r2: back online on v2, not gated since: gating it" in capsys.readouterr().err
    gated.clear()
    fleet_status.status(Options(project_dir=fleet_project.project.root))  # once: the next look gates nobody
    assert gated == []
