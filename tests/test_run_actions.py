"""run's restarts for a discovery kind whose nodes register only when they start (the ROS 1 master)."""

from __future__ import annotations

import threading
from datetime import datetime, timezone

import pytest

from robocore.commands.run import SIDE_BY_SIDE
from robocore.commands.support.hosts import each_or_first_error
from robocore.commands.support.status_table import Row, not_registered
from robocore.errors import DockerError
from robocore.plan.actions import Action, Existing, in_stages, servers_started, with_node_restarts
from robocore.plan.containers import ContainerSpec
from robocore.plan.naming import ROLE_COMPONENT, ROLE_DISCOVERY
from robocore.plan.starts import docker_epoch, docker_time


def spec(name: str, role: str) -> ContainerSpec:
    return ContainerSpec(name=name, service=name, host="a", role=role, project="p", image="i", entrypoint=None,
                         command=None, environment=(), network_mode="host")


SPECS = [spec("p-discovery-0", ROLE_DISCOVERY), spec("p-talker", ROLE_COMPONENT), spec("p-listener", ROLE_COMPONENT)]


def verbs(actions: list[Action]) -> dict[str, str]:
    return {a.name: a.verb for a in actions}


def test_a_restarted_master_restarts_the_kept_nodes_of_its_host() -> None:
    actions = [Action("start", "p-discovery-0", "was stopped"), Action("keep", "p-talker"),
               Action("create", "p-listener")]
    assert servers_started(actions, {"p-discovery-0"})
    done = with_node_restarts(actions, SPECS, register_once=True)
    assert verbs(done) == {"p-discovery-0": "start", "p-talker": "replace", "p-listener": "create"}
    assert "register" in done[1].reason
    # control: a kind whose nodes find a restarted server by themselves (Fast DDS) keeps them
    assert with_node_restarts(actions, SPECS, register_once=False) == actions


def test_a_kept_master_keeps_its_nodes() -> None:
    actions = [Action("keep", "p-discovery-0"), Action("keep", "p-talker"), Action("replace", "p-listener", "new")]
    assert not servers_started(actions, {"p-discovery-0"})
    assert with_node_restarts(actions, SPECS, register_once=True) == actions


def test_a_master_restarted_on_another_host_restarts_this_hosts_nodes() -> None:
    here = [spec("p-listener", ROLE_COMPONENT)]
    actions = [Action("keep", "p-listener"), Action("remove", "p-old", "no longer planned on this host")]
    done = with_node_restarts(actions, here, register_once=True, elsewhere=True)
    assert verbs(done) == {"p-listener": "replace", "p-old": "remove"}
    assert with_node_restarts(actions, here, register_once=True, elsewhere=False) == actions


def existing(name: str, role: str, started_at: str, running: bool = True) -> Existing:
    return Existing(name=name, spec_hash="h", image_id="i", running=running, role=role, started_at=started_at)


KEPT = [Action("keep", "p-discovery-0"), Action("keep", "p-talker"), Action("keep", "p-listener")]
MASTER_AT = "2026-11-25T10:00:05.123456789Z"


def test_nodes_started_before_the_masters_last_start_are_replaced() -> None:
    """The master restarted behind robocore's back (Docker's restart policy, docker restart): it is kept, and
    the nodes it forgot are replaced; a node that started after it is registered and kept."""
    found = [existing("p-discovery-0", ROLE_DISCOVERY, MASTER_AT),
             existing("p-talker", ROLE_COMPONENT, "2026-11-25T09:59:00Z"),
             existing("p-listener", ROLE_COMPONENT, "2026-11-25T10:00:05.400Z")]
    done = with_node_restarts(KEPT, SPECS, register_once=True, existing=found)
    assert verbs(done) == {"p-discovery-0": "keep", "p-talker": "replace", "p-listener": "keep"}
    assert "before the discovery server's last start" in done[1].reason
    assert with_node_restarts(KEPT, SPECS, register_once=False, existing=found) == KEPT  # control: Fast DDS


def test_a_stopped_master_or_an_unknown_start_dates_nothing() -> None:
    old = existing("p-talker", ROLE_COMPONENT, "2026-11-25T09:00:00Z")
    stopped = [existing("p-discovery-0", ROLE_DISCOVERY, MASTER_AT, running=False), old]
    assert with_node_restarts(KEPT, SPECS, register_once=True, existing=stopped) == KEPT
    unknown = [existing("p-discovery-0", ROLE_DISCOVERY, ""), old]
    assert with_node_restarts(KEPT, SPECS, register_once=True, existing=unknown) == KEPT


def test_another_hosts_master_dates_this_hosts_nodes() -> None:
    here = [spec("p-listener", ROLE_COMPONENT)]
    found = [existing("p-listener", ROLE_COMPONENT, "2026-11-25T09:59:59Z")]
    master = docker_time(MASTER_AT)
    assert verbs(with_node_restarts([Action("keep", "p-listener")], here, register_once=True, existing=found,
                                    server_start=master)) == {"p-listener": "replace"}
    later = [existing("p-listener", ROLE_COMPONENT, "2026-11-25T10:00:06Z")]
    assert verbs(with_node_restarts([Action("keep", "p-listener")], here, register_once=True, existing=later,
                                    server_start=master)) == {"p-listener": "keep"}


def test_docker_times() -> None:
    assert docker_time(MASTER_AT) == datetime(2026, 11, 25, 10, 0, 5, 123456, tzinfo=timezone.utc)
    assert docker_time("2026-11-25T10:00:05Z") == datetime(2026, 11, 25, 10, 0, 5, tzinfo=timezone.utc)
    assert docker_time("") is None and docker_time("yesterday") is None


def test_docker_epochs_are_the_times_in_seconds_and_refuse_what_they_cannot_read() -> None:
    assert docker_epoch(MASTER_AT) == docker_time(MASTER_AT).timestamp()  # type: ignore[union-attr]
    assert docker_epoch("2026-11-25T10:00:05Z") - docker_epoch(MASTER_AT) == pytest.approx(-0.123456)
    with pytest.raises(ValueError, match="not a Docker timestamp: 'yesterday'"):
        docker_epoch("yesterday")


def row(name: str, started_at: str | None) -> Row:
    return Row(component=name, host="a", state="running" if started_at else "exited", uptime="-", restarts=0,
               image="i", started_at=started_at)


def test_status_names_the_nodes_a_restarted_master_does_not_know() -> None:
    rows = [row("discovery-0", MASTER_AT), row("talker", "2026-11-25T09:59:00Z"),
            row("listener", "2026-11-25T10:00:06Z"), row("camera", None)]
    assert not_registered(rows, ["discovery-0"]) == ["talker"]
    # a stopped master dates nothing (status says it is down instead)
    assert not_registered([row("discovery-0", None), *rows[1:]], ["discovery-0"]) == []


def test_stages_take_removals_then_each_server_alone_then_everything_else() -> None:
    actions = [Action("remove", "p-old", "no longer planned"), Action("replace", "p-discovery-0", "new image"),
               Action("create", "p-discovery-1"), Action("create", "p-talker"), Action("keep", "p-listener"),
               Action("start", "p-camera", "was stopped")]
    stages = in_stages(actions, {"p-discovery-0", "p-discovery-1"})
    assert [[a.name for a in stage] for stage in stages] == [
        ["p-old"], ["p-discovery-0"], ["p-discovery-1"], ["p-talker", "p-camera"]]
    # control: with nothing to remove and the servers kept, one stage holds every component
    kept = [Action("keep", "p-discovery-0"), Action("create", "p-talker"), Action("create", "p-listener")]
    assert in_stages(kept, {"p-discovery-0"}) == [[kept[1], kept[2]]]
    assert in_stages([Action("keep", "p-talker")], set()) == []


def test_a_stage_overlaps_and_raises_the_first_failure_after_all_ran() -> None:
    barrier = threading.Barrier(SIDE_BY_SIDE, timeout=10)  # broken unless SIDE_BY_SIDE run at the same time
    done: list[str] = []

    def apply(action: Action) -> None:
        barrier.wait()
        done.append(action.name)
        if action.name in ("c1", "c3"):
            raise DockerError(f"{action.name} failed")

    actions = [Action("create", f"c{i}") for i in range(SIDE_BY_SIDE)]
    with pytest.raises(DockerError, match="c1 failed"):
        each_or_first_error(actions, apply, limit=SIDE_BY_SIDE)
    assert sorted(done) == [a.name for a in actions]
