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
from robocore.plan import naming
from robocore.plan import swarm_services as plan
from robocore.project import Project

if TYPE_CHECKING:
    import docker

    from robocore.adapters.swarm import ServiceInfo
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


def manager_line(fleet: FleetProject) -> str:
    """How a dry run says the manager is reached (it is not contacted)."""
    from robocore.adapters.docker_hosts import describe

    manager = fleet.fleet.manager
    assert manager is not None
    return f"manager {manager.ip}: docker via {describe(manager.as_host())} (dry run: not contacted)"


def now() -> str:
    """The current time, UTC, ISO 8601 to the second (what ``last change`` shows)."""
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def project_label(fleet: FleetProject) -> str:
    """The label filter of the project's services."""
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


def unheard(robot: str, by_robot: dict[str, list[Any]], fleet: FleetProject) -> list[str]:
    """The hosts of ``robot`` whose node the manager has not heard from since it started (state ``unknown``: swarmkit
    marks every node so when a manager takes the lead, until the node's agent reconnects). Not the same as offline:
    the manager does not know yet."""
    wanted = {h.name for h in fleet.instances[robot].hosts_in_use()}
    return sorted(str(n.labels.get(plan.NODE_HOST)) for n in by_robot.get(robot, [])
                  if n.state == "unknown" and n.labels.get(plan.NODE_HOST) in wanted)


def recorded_release(fleet: FleetProject, robot: str, live: dict[str, ServiceInfo], *,
                      previous: bool) -> plan.Release | None:
    """From ``robot``'s services' labels (``live``: the project's services by name): the release it runs (or, with
    ``previous``, the one it ran before), None when there is none. What a rollback returns to and a failed robot
    goes back to."""
    mine = [s for s in live.values() if s.labels.get(plan.LABEL_ROBOT) == robot]
    version_label = plan.LABEL_PREVIOUS if previous else plan.LABEL_RELEASE
    image_label = plan.LABEL_PREVIOUS_IMAGE if previous else plan.LABEL_IMAGE
    versions = {s.labels.get(version_label, "") for s in mine}
    if not mine or versions == {""} or len(versions) != 1:
        return None
    components: dict[str, dict[str, str]] = {}
    base: dict[str, str] = {}
    instance = fleet.instances[robot]
    for service in mine:
        image = service.labels.get(image_label, "") or (service.image if not previous else "")
        component = service.labels.get(naming.LABEL_COMPONENT, "")
        if service.labels.get(naming.LABEL_ROLE) == naming.ROLE_DISCOVERY:
            for host in instance.hosts:
                base.setdefault(host.arch.value, image)
        else:
            try:
                arch = instance.host(instance.component(component).runs_on).arch.value
            except KeyError:
                continue
            components[component] = {arch: image}
    for host in instance.hosts:  # a probe on a host without a discovery server
        if base:
            base.setdefault(host.arch.value, next(iter(base.values())))
    return plan.Release(version=versions.pop(), components=components, base=base)
