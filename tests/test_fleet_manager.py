"""The manager as a fault (``fleet_manager``), against a fake swarm: a command that loses the manager ends in one
line with what to do, a rollout after the manager's restart waits for it to hear from the robots again and clears
the probes of the run that was cut off, and ``fleet status`` says "unknown", not "offline", of a robot the manager
has not heard from since it started. The real restart is integration/test_fleet_swarm.py's."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import fleet_world
import pytest
import requests
from docker.errors import APIError
from fleet_world import TWO_ROBOTS, Clock

from robocore.adapters import swarm
from robocore.commands import fleet_manager
from robocore.commands.fleet_manager import lost, manager_faults, settle
from robocore.commands.fleet_status import Observed, status_rows
from robocore.commands.fleet_swarm import FleetProject
from robocore.commands.support.reporting import Reporter
from robocore.errors import DockerError, HostError, UsageError
from robocore.plan import naming
from robocore.plan import swarm_services as plan
from robocore.plan.fleet_page import RobotView, verdict

FLEET = TWO_ROBOTS


@pytest.fixture
def fleet_project(tmp_path: Path) -> FleetProject:
    return fleet_world.fleet_project(tmp_path / "p", FLEET)


def node(project: str, robot: str, state: str) -> swarm.NodeInfo:
    return swarm.NodeInfo(id=f"n{robot}", hostname=robot, labels=plan.node_labels(project, robot, "main", "amd64"),
                          state=state, availability="active", addr="")


# --------------------------------------------------------------------------- a command that loses the manager


def test_the_manager_lost_mid_rollout_is_one_line_saying_to_run_it_again() -> None:
    with pytest.raises(HostError) as caught, manager_faults("rollout", "v4"):
        raise requests.exceptions.ConnectionError("('Connection aborted.', RemoteDisconnected('closed'))\nmore")
    assert caught.value.lines() == [
        "lost the swarm's manager during fleet rollout: ('Connection aborted.', RemoteDisconnected('closed'))",
        "hint: once the manager answers again, run `robocore fleet rollout v4` again: it finishes what this one "
        "started (robots already on v4 are gated again, not restarted)"]


def test_status_without_a_manager_says_it_cannot_know() -> None:
    unreachable = HostError("host manager: cannot reach its Docker daemon at ssh://root@10.0.0.2: No route to host",
                            hint="check the host")
    with pytest.raises(HostError) as caught, manager_faults("status", None):
        raise unreachable
    assert caught.value.message == unreachable.message
    assert caught.value.hint == ("fleet status reads the fleet's state from the manager only: until it answers, that "
                                 "state is not known")


def test_a_manager_starting_or_stopping_says_so() -> None:
    with pytest.raises(DockerError) as caught, manager_faults("status", None):
        raise DockerError("docker node ls: rpc error: code = Unknown desc = The swarm does not have a leader.")
    assert caught.value.lines() == [
        "the swarm's manager is not serving as one (its daemon starting or stopping) during fleet status: docker node "
        "ls: rpc error: code = Unknown desc = The swarm does not have a leader.",
        "hint: fleet status reads the fleet's state from the manager only: until it answers, that state is not known"]
    stopping = ('docker node ls: rpc error: code = Unavailable desc = connection error: desc = "transport: Error '
                'while dialing dial unix /var/run/docker/swarm/control.sock: connect: no such file or directory"')
    with pytest.raises(DockerError) as caught, manager_faults("rollout", "v2"):
        raise DockerError(stopping)  # what a rollout saw in the Swarm suite as the manager's daemon stopped
    assert caught.value.message.endswith(stopping) and "robocore fleet rollout v2` again" in str(caught.value.hint)


def test_other_errors_are_left_as_they_are() -> None:
    robot = HostError("host main: cannot reach its Docker daemon", hint="check the robot")
    for error in (robot, UsageError("bad"), DockerError("docker service ls: denied")):
        with pytest.raises(type(error)) as caught, manager_faults("rollout", "v4"):
            raise error
        assert caught.value is error
    with pytest.raises(KeyError), manager_faults("rollout", "v4"):  # a bug keeps its traceback
        raise KeyError("talker")


def test_what_counts_as_the_manager_lost() -> None:
    assert lost(requests.exceptions.ConnectionError("reset"))
    assert lost(ConnectionRefusedError(111, "refused"))
    no_leader = requests.Response()
    no_leader.status_code = 503
    assert lost(APIError("503 Server Error", no_leader, "The swarm does not have a leader."))
    missing = requests.Response()
    missing.status_code = 404
    assert not lost(APIError("404 Client Error", missing, "service not found"))
    assert not lost(ValueError("bad"))


# --------------------------------------------------------------------------- a rollout after a restart


@pytest.fixture
def fake_swarm(fleet_project: FleetProject, monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    """A swarm whose node states follow ``world["states"]`` (one list per look, the last kept), with services and
    their tasks in ``world["services"]``/``world["tasks"]``; removed services land in ``world["removed"]``."""
    project = fleet_project.name
    world: dict[str, Any] = {"states": [["unknown", "unknown"]], "looks": 0, "services": [], "tasks": {},
                             "removed": []}

    def nodes(_client: Any) -> list[swarm.NodeInfo]:
        states = world["states"][min(world["looks"], len(world["states"]) - 1)]
        world["looks"] += 1
        if states == "no leader":
            raise DockerError("docker node ls: rpc error: code = Unknown desc = The swarm does not have a leader.")
        return [node(project, robot, state) for robot, state in zip(("r1", "r2"), states, strict=True)]

    clock = Clock()
    monkeypatch.setattr(fleet_manager, "time", clock)
    monkeypatch.setattr(swarm, "nodes", nodes)
    monkeypatch.setattr(swarm, "services", lambda _client, _label: world["services"])
    monkeypatch.setattr(swarm, "tasks", lambda _client, name: world["tasks"].get(name, []))
    monkeypatch.setattr(swarm, "remove_service", lambda _client, name: world["removed"].append(name))
    world["clock"] = clock
    return world


def service(project: str, name: str, *, probe: bool) -> swarm.ServiceInfo:
    labels = {naming.LABEL_PROJECT: project, plan.LABEL_ROBOT: "r1", **({plan.LABEL_PROBE: "1"} if probe else {})}
    return swarm.ServiceInfo(id=name, name=name, labels=labels, image="img", version=1, attrs={})


def task(state: str) -> swarm.TaskInfo:
    return swarm.TaskInfo(id="t", node_id="n", state=state, desired="shutdown", image="img", created="1", error="",
                          exit_code=0, container="c")


def test_a_rollout_waits_until_the_restarted_manager_hears_from_its_robots(
        fleet_project: FleetProject, fake_swarm: dict[str, Any], capsys: pytest.CaptureFixture[str]) -> None:
    fake_swarm["states"] = ["no leader", ["unknown", "unknown"], ["ready", "unknown"], ["ready", "ready"]]
    began = fake_swarm["clock"].now
    settle(object(), fleet_project, Reporter("fleet"))  # type: ignore[arg-type]
    assert fake_swarm["looks"] == 4 and fake_swarm["clock"].now - began == 3 * fleet_manager.POLL
    said = capsys.readouterr().err
    assert said.count("waiting up to 30 s for the manager") == 1 and "(the manager has no leader yet)" in said


def test_the_wait_is_bounded_and_a_ready_fleet_does_not_wait(fleet_project: FleetProject,
                                                             fake_swarm: dict[str, Any]) -> None:
    fake_swarm["states"] = [["ready", "unknown"]]  # r2 never heard from again: after SETTLE, taken for offline
    began = fake_swarm["clock"].now
    settle(object(), fleet_project, Reporter("fleet"))  # type: ignore[arg-type]
    assert fleet_manager.SETTLE <= fake_swarm["clock"].now - began <= fleet_manager.SETTLE + fleet_manager.POLL
    fake_swarm["states"], fake_swarm["looks"] = [["ready", "down"]], 0  # down is the manager's knowledge: no wait
    began = fake_swarm["clock"].now
    settle(object(), fleet_project, Reporter("fleet"))  # type: ignore[arg-type]
    assert fake_swarm["clock"].now == began and fake_swarm["looks"] == 1


def test_an_error_other_than_no_leader_is_not_waited_out(fleet_project: FleetProject,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    def denied(_client: Any) -> list[swarm.NodeInfo]:
        raise DockerError("docker node ls: permission denied")

    monkeypatch.setattr(swarm, "nodes", denied)
    with pytest.raises(DockerError, match="permission denied"):
        settle(object(), fleet_project, Reporter("fleet"))  # type: ignore[arg-type]


def test_the_ended_probes_of_a_run_cut_off_are_removed(fleet_project: FleetProject,
                                                       fake_swarm: dict[str, Any]) -> None:
    project = fleet_project.name
    fake_swarm["states"] = [["ready", "ready"]]
    fake_swarm["services"] = [service(project, "p-probe-r1-old", probe=True),
                              service(project, "p-probe-r1-live", probe=True),
                              service(project, "p-r1-talker", probe=False)]
    fake_swarm["tasks"] = {"p-probe-r1-old": [task("complete")], "p-probe-r1-live": [task("running")],
                           "p-r1-talker": [task("complete")]}
    settle(object(), fleet_project, Reporter("fleet"))  # type: ignore[arg-type]
    assert fake_swarm["removed"] == ["p-probe-r1-old"]  # not a probe still running, never a robot's service


# --------------------------------------------------------------------------- status after a restart


def test_status_says_unknown_of_a_robot_the_restarted_manager_has_not_heard_from(fleet_project: FleetProject) -> None:
    project = fleet_project.name
    nodes = {"r1": [node(project, "r1", "unknown")], "r2": [node(project, "r2", "down")]}
    rows = status_rows(fleet_project, Observed(by_robot=nodes, services=[], tasks={}))
    assert [(r.robot, r.state) for r in rows] == [("r1", "unknown"), ("r2", "offline")]
    nodes["r1"] = [node(project, "r1", "ready")]
    assert status_rows(fleet_project, Observed(by_robot=nodes, services=[], tasks={}))[0].state == "online"
    shown = verdict(RobotView(robot="r1", wave="w", labels=(), running="v1", target="v1", health="healthy",
                              state="unknown"))
    assert (shown.tone, shown.words) == ("off", "unknown")
