"""What the ``fleet`` tasks share: the project with its fleet file, the manager's client, each robot's services.

A Swarm fleet is driven through its manager only (``fleet rollout``, ``status``, ``rollback``); robot hosts are
contacted directly only to join them (``fleet join``). Every robot's state lives in the labels of its services
(:mod:`robocore.plan.swarm_services`), so that any machine that reaches the manager sees the truth.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timezone
from typing import TYPE_CHECKING, Any

from robocore.commands.support.context import Options
from robocore.config.model import Robot
from robocore.errors import ConfigError, UsageError
from robocore.plan import swarm_services as plan
from robocore.project import Project

if TYPE_CHECKING:
    import docker

    from robocore.config.fleet import Fleet

#: Seconds each API call to the manager may take.
MANAGER_TIMEOUT = 120


@dataclass(frozen=True)
class FleetProject:
    """A project with its fleet file, each robot as its own robot.yaml model."""

    project: Project
    fleet: Fleet
    instances: dict[str, Robot]

    @property
    def name(self) -> str:
        """The project's name (part of every service and config name)."""
        return self.project.name


def load(options: Options) -> FleetProject:
    """The project, its fleet file (checked against robot.yaml) and, on a Swarm fleet, nothing Swarm refuses."""
    from robocore.config.fleet import load_fleet
    from robocore.plan.fleet import fleet_instances, swarm_problems

    project = Project.load(options.project_dir)
    fleet = load_fleet(project.root, project.robot)
    if fleet.engine != "swarm":
        raise UsageError(f"the fleet file's engine is {fleet.engine!r}: robocore runs only swarm fleets itself",
                         hint="robocore export kubernetes DIR renders a kubernetes fleet")
    problems = swarm_problems(project.robot, fleet, project.robot_file)
    if problems:
        raise ConfigError(problems)
    if fleet.manager is None:
        raise UsageError("the fleet file names no manager: a swarm fleet needs `manager: {ip: ...}`")
    return FleetProject(project=project, fleet=fleet, instances=fleet_instances(project.robot, fleet))


def manager_client(fleet: FleetProject) -> docker.DockerClient:
    """A client of the manager's daemon (HostError naming the manager when it cannot be reached)."""
    from robocore.adapters.docker_hosts import client_for

    assert fleet.fleet.manager is not None
    return client_for(fleet.fleet.manager.as_host(), MANAGER_TIMEOUT, project_root=fleet.project.root)


def now() -> str:
    """The current time, UTC, ISO 8601 to the second (what ``last change`` shows)."""
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def project_label(fleet: FleetProject) -> str:
    """The label filter of the project's services."""
    from robocore.plan import naming

    return f"{naming.LABEL_PROJECT}={fleet.name}"


def robot_nodes(nodes: list[Any], fleet: FleetProject) -> dict[str, list[Any]]:
    """The project's swarm nodes by robot name (from robocore's node labels)."""
    out: dict[str, list[Any]] = {}
    for node in nodes:
        if node.labels.get(plan.NODE_PROJECT) == fleet.name and plan.NODE_ROBOT in node.labels:
            out.setdefault(node.labels[plan.NODE_ROBOT], []).append(node)
    return out


def offline(robot: str, by_robot: dict[str, list[Any]], fleet: FleetProject) -> list[str]:
    """The hosts of ``robot`` whose node is not ready (or not joined): an empty list when the robot is reachable."""
    wanted = [h.name for h in fleet.instances[robot].hosts_in_use()]
    ready = {n.labels.get(plan.NODE_HOST) for n in by_robot.get(robot, []) if n.state == "ready"
             and n.availability == "active"}
    return [host for host in wanted if host not in ready]
