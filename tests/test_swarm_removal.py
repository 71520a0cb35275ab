"""Stop-first when a service is made anew: the removed service's containers have stopped before its successor exists.

``swarm.remove_stopped`` against a fake docker client whose removed tasks keep running for a while (Swarm removes
a service at once and stops its containers afterwards), on a fake clock; and the rollout's way back, which calls
it for every changed service before it makes any of them again.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import fleet_world
import pytest
from fleet_world import Clock

from robocore.adapters import swarm
from robocore.commands import fleet_rollout
from robocore.commands.fleet_gate import FAILED, Change
from robocore.plan import swarm_services as plan


class _Node:
    def __init__(self, node_id: str, state: str) -> None:
        self.attrs = {"ID": node_id, "Status": {"State": state}, "Spec": {}}


class _Service:
    def __init__(self, client: FakeClient, name: str) -> None:
        self.client, self.name = client, name

    def remove(self) -> None:
        self.client.removed[self.name] = self.client.clock.now


class FakeClient:
    """Services ``a`` and ``b``: each one task running on node ``n-a``/``n-b``; a removed service's task stops
    ``stops_after`` seconds after its removal (never, when None)."""

    def __init__(self, clock: Clock, down: frozenset[str] = frozenset(), stops_after: float | None = 3.0) -> None:
        self.clock, self.down, self.stops_after = clock, down, stops_after
        self.removed: dict[str, float] = {}
        self.api, self.services, self.nodes = self, self, self

    def list(self) -> list[_Node]:  # client.nodes.list()
        return [_Node(f"n-{name}", "down" if name in self.down else "ready") for name in ("a", "b")]

    def get(self, name: str) -> _Service:  # client.services.get(name)
        return _Service(self, name)

    def tasks(self, filters: dict[str, Any]) -> list[dict[str, Any]]:  # client.api.tasks(filters=...)
        found = []
        for name in ("a", "b"):
            gone = name in self.removed and self.stops_after is not None \
                and self.clock.now >= self.removed[name] + self.stops_after
            task = {"ID": f"t-{name}", "NodeID": f"n-{name}", "DesiredState": "remove" if name in self.removed
                    else "running", "Status": {"State": "shutdown" if gone else "running"}, "CreatedAt": "1"}
            if filters.get("service") == name or f"t-{name}" in filters.get("id", []):
                found.append(task)
        return found


@pytest.fixture
def clock(monkeypatch: pytest.MonkeyPatch) -> Clock:
    fake = Clock()
    monkeypatch.setattr(swarm, "time", fake)
    return fake


def test_the_removed_services_containers_have_stopped_when_it_returns(clock: Clock) -> None:
    client = FakeClient(clock)
    began = clock.now
    assert swarm.remove_stopped(client, ["a", "b"]) == []  # type: ignore[arg-type]
    assert set(client.removed) == {"a", "b"}
    assert clock.now >= max(client.removed.values()) + 3  # it waited for the stop, not only for the removal
    assert clock.now - began < 4


def test_a_task_on_a_node_that_is_down_is_not_waited_for(clock: Clock) -> None:
    client = FakeClient(clock, down=frozenset({"a", "b"}))
    assert swarm.remove_stopped(client, ["a", "b"]) == []  # type: ignore[arg-type]
    assert set(client.removed) == {"a", "b"} and clock.now == 1000.0


def test_a_container_that_never_stops_is_waited_for_up_to_the_bound_and_named(clock: Clock) -> None:
    client = FakeClient(clock, stops_after=None)
    assert swarm.remove_stopped(client, ["a"]) == ["t-a"]  # type: ignore[arg-type]
    assert swarm.STOPPED_WAIT <= clock.now - 1000.0 <= swarm.STOPPED_WAIT + 1


FLEET = """\
manager: {ip: 10.0.0.2}
registry: 10.0.0.2:5000
robots:
  - {name: r1, hosts: {main: {ip: 10.1.1.1}}}
"""
DIGEST = "@sha256:"


def _release(version: str, talker: str) -> plan.Release:
    return plan.Release(version=version, components={"talker": {"amd64": f"10.0.0.2:5000/p-talker{DIGEST}{talker}"}},
                        base={"amd64": f"10.0.0.2:5000/p-base{DIGEST}{'0' * 64}"})


def test_the_way_back_makes_no_service_anew_before_the_failed_ones_have_stopped(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The canary failed on v3 (its talker runs): its talker, changed, is removed and waited for before any
    service of v2 is made; the discovery server, the same in both, is updated in place (no removal)."""
    fleet = fleet_world.fleet_project(tmp_path / "p", FLEET)
    v2, v3 = _release("v2", "2" * 64), _release("v3", "3" * 64)
    calls: list[tuple[str, str]] = []
    live = {}
    for spec in plan.robot_services(fleet.project, "r1", fleet.instances["r1"], v2):
        labelled = plan.release_labels(spec, version="v2", previous="", previous_image="", changed="t", health="")
        live[spec.name] = swarm.ServiceInfo(id=spec.name, name=spec.name, labels=labelled.label_map,
                                            image=spec.image, version=1, attrs={})
    failed = plan.robot_services(fleet.project, "r1", fleet.instances["r1"], v3)
    monkeypatch.setattr(swarm, "remove_stopped", lambda _c, names: calls.extend(("stopped", n) for n in names) or [])
    monkeypatch.setattr(swarm, "remove_service", lambda _c, name: calls.append(("removed", name)))
    monkeypatch.setattr(swarm, "tasks", lambda _c, _name: [])
    monkeypatch.setattr(swarm, "ensure_configs", lambda _c, _configs: {})
    monkeypatch.setattr(swarm, "apply_service", lambda _c, spec, _ids: calls.append(("made", spec.name)) or "id")

    class NoGate:
        releases: dict[str, plan.Release] = {}

        def run(self, changes: list[Change]) -> None:
            for change in changes:
                change.verdict = "healthy"

    change = Change(robot="r1", wave="canary", release="v3", specs=failed, before={}, started=0.0, deadline=1.0,
                    verdict=FAILED)
    back = fleet_rollout.roll_back(object(), fleet, [change], NoGate(), live)  # type: ignore[arg-type]
    talker = next(s.name for s in failed if s.component == "talker")
    assert calls[0] == ("stopped", talker) and ("removed", talker) not in calls, calls
    assert [name for kind, name in calls if kind == "stopped"] == [talker]  # the discovery server is the same
    assert {name for kind, name in calls if kind == "made"} == {s.name for s in failed}
    assert [c.release for c in back] == ["v2"]
