"""Which Swarm services ``fleet logs`` and ``fleet connect`` read: a robot's parts (its discovery servers and its
components), each with the robot host it runs on and its service name; a name the fleet does not have is refused in
one line that lists the names it does have. Pure: no I/O."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from robocore.config.model import Robot
from robocore.errors import UsageError
from robocore.plan import discovery
from robocore.plan.containers import discovery_service
from robocore.plan.swarm_services import service_name


@dataclass(frozen=True)
class Part:
    """One service of a robot: ``name`` is its component (or ``discovery-<i>``), ``host`` the robot.yaml host that
    runs it, ``service`` its Swarm service."""

    name: str
    host: str
    service: str


def _listed(names: list[str]) -> str:
    return ", ".join(names) if names else "none"


def robot_of(instances: Mapping[str, Robot], robot: str) -> Robot:
    """The model of ``robot``, or a UsageError in one line listing the fleet's robots."""
    if robot not in instances:
        raise UsageError(f"no robot {robot!r} in fleet.yaml (its robots: {_listed(list(instances))})")
    return instances[robot]


def robot_parts(project: str, instances: Mapping[str, Robot], robot: str, component: str | None = None) -> list[Part]:
    """``robot``'s parts (discovery servers first, then the components in file order), or only ``component``
    (a component or ``discovery-<i>``); a robot or component the fleet does not have is a one-line UsageError
    naming what exists."""
    instance = robot_of(instances, robot)
    parts = [Part(discovery_service(s.index), s.host, service_name(project, robot, discovery_service(s.index)))
             for s in discovery.for_robot(instance).servers()]
    parts += [Part(c.name, c.runs_on, service_name(project, robot, c.name)) for c in instance.components]
    if component is None:
        return parts
    chosen = [p for p in parts if p.name == component]
    if not chosen:
        raise UsageError(f"robot {robot} has no component {component!r} (its components: "
                         f"{_listed([p.name for p in parts])})")
    return chosen


def component_of(project: str, instances: Mapping[str, Robot], robot: str, component: str) -> Part:
    """The one part ``component`` of ``robot`` (:func:`robot_parts`' checks)."""
    return robot_parts(project, instances, robot, component)[0]
