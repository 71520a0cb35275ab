"""run's restarts for a discovery kind whose nodes register only when they start (the ROS 1 master)."""

from __future__ import annotations

from robocore.plan.actions import Action, servers_started, with_node_restarts
from robocore.plan.containers import ROLE_COMPONENT, ROLE_DISCOVERY, ContainerSpec


def spec(name: str, role: str) -> ContainerSpec:
    return ContainerSpec(name=name, service=name, host="a", role=role, project="p", image="i", entrypoint=None,
                         command=None, environment=(), network_mode="host")


SPECS = [spec("p-discovery-0", ROLE_DISCOVERY), spec("p-talker", ROLE_COMPONENT), spec("p-listener", ROLE_COMPONENT)]


def verbs(actions: list[Action]) -> dict[str, str]:
    return {a.name: a.verb for a in actions}


def test_a_restarted_master_restarts_the_kept_nodes_of_its_host() -> None:
    actions = [Action("start", "p-discovery-0", "was stopped"), Action("keep", "p-talker"),
               Action("create", "p-listener")]
    assert servers_started(actions, SPECS)
    done = with_node_restarts(actions, SPECS, register_once=True)
    assert verbs(done) == {"p-discovery-0": "start", "p-talker": "replace", "p-listener": "create"}
    assert "register" in done[1].reason
    # control: a kind whose nodes find a restarted server by themselves (Fast DDS) keeps them
    assert with_node_restarts(actions, SPECS, register_once=False) == actions


def test_a_kept_master_keeps_its_nodes() -> None:
    actions = [Action("keep", "p-discovery-0"), Action("keep", "p-talker"), Action("replace", "p-listener", "new")]
    assert not servers_started(actions, SPECS)
    assert with_node_restarts(actions, SPECS, register_once=True) == actions


def test_a_master_restarted_on_another_host_restarts_this_hosts_nodes() -> None:
    here = [spec("p-listener", ROLE_COMPONENT)]
    actions = [Action("keep", "p-listener"), Action("remove", "p-old", "no longer planned on this host")]
    done = with_node_restarts(actions, here, register_once=True, elsewhere=True)
    assert verbs(done) == {"p-listener": "replace", "p-old": "remove"}
    assert with_node_restarts(actions, here, register_once=True, elsewhere=False) == actions
