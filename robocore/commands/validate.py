"""validate: load robot.yaml (and fleet.yaml when the project has one) and say what they describe."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from robocore.commands.support.context import Options

if TYPE_CHECKING:
    from robocore.project import Project


@dataclass(frozen=True)
class HostSummary:
    """A host of the robot and the components it runs."""

    name: str
    ip: str
    arch: str
    docker: str
    components: list[str]


@dataclass(frozen=True)
class RobotSummary:
    """What a valid robot.yaml describes."""

    kind: ClassVar[str] = "robot"
    file: str
    ros_distro: str
    base: str
    hosts: list[HostSummary]
    discovery_servers: list[str]


@dataclass(frozen=True)
class WaveSummary:
    """One wave of the fleet's rollout and its robots."""

    name: str
    robots: list[str]


@dataclass(frozen=True)
class FleetSummary:
    """What a valid fleet.yaml describes."""

    kind: ClassVar[str] = "fleet"
    file: str
    engine: str
    robots: list[str]
    waves: list[WaveSummary]


def run(options: Options) -> None:
    """Validate robot.yaml; a ConfigError carries every problem (the task turns it into exit code 2)."""
    report = options.report
    if options.dry_run:
        report.notice(f"would validate {options.project_dir / 'robot.yaml'}")
        return
    project = options.load()
    robot = project.robot
    from robocore.config.loader import robot_warnings
    from robocore.plan.dockerfiles import refuse_robot_shape

    refuse_robot_shape(project)  # what prepare-base and stage refuse for the robot's shape
    from robocore.commands.support.workspace import check_wheels_packages, debian_dependency_warnings

    check_wheels_packages(project)
    for warning in [*robot_warnings(project.robot_file, robot, project.root), *debian_dependency_warnings(project)]:
        report.warn(warning.message, warning)
    by_host: dict[str, list[str]] = {}
    for comp in robot.components:
        by_host.setdefault(comp.runs_on, []).append(comp.name)
    summary = RobotSummary(
        file=str(project.robot_file), ros_distro=robot.ros_distro.value, base=robot.base.kind.value,
        hosts=[HostSummary(h.name, h.ip, h.arch.value, h.access.value, by_host.get(h.name, [])) for h in robot.hosts],
        discovery_servers=[f"{s.host}:{s.port}" for s in robot.discovery_servers])
    report.add(summary)
    lines = [
        f"{summary.file}: ok — {robot.generation} {summary.ros_distro}, {len(robot.hosts)} host(s), "
        f"{len(robot.components)} component(s), base {summary.base}"
    ]
    for host in summary.hosts:
        names = ", ".join(host.components) or "no components"
        lines.append(f"  {host.name} ({host.ip}, {host.arch}, docker via {host.docker}): {names}")
    lines.append(f"  discovery ({robot.discovery_kind}): {', '.join(summary.discovery_servers)}")
    for line in lines:
        report.info(line)
    if project.has_fleet:
        _validate_fleet(options, project)


def _validate_fleet(options: Options, project: Project) -> None:
    """Load fleet.yaml against robot.yaml, refuse what its engine cannot run, and say what it describes."""
    from robocore.errors import ConfigError
    from robocore.plan.fleet import plan_waves, swarm_problems

    fleet = project.load_fleet()
    problems = swarm_problems(project.robot, fleet, project.robot_file)
    if problems:
        raise ConfigError(problems)
    from robocore.config.loader import fleet_model_warnings, fleet_warnings

    for warning in fleet_warnings(project.fleet_file, fleet.manager.as_host() if fleet.manager else None,
                                  [robot.ros_domain_id for robot in fleet.robots], project.robot.ros_version):
        options.report.warn(warning.message, warning)
    users = {host.name: all(r.hosts[host.name].user is not None for r in fleet.robots if host.name in r.hosts)
             for host in project.robot.hosts}
    for warning in fleet_model_warnings(project.robot_file, project.robot, users):
        options.report.warn(warning.message, warning)
    waves = [WaveSummary(wave.name, list(wave.robots)) for wave in plan_waves(fleet)]
    summary = FleetSummary(file=str(project.fleet_file), engine=fleet.engine, robots=fleet.robot_names, waves=waves)
    options.report.add(summary)
    options.report.info(f"{summary.file}: ok — {fleet.engine}, {len(fleet.robots)} robot(s), "
                        f"{len(waves)} wave(s): " + ", ".join(f"{w.name} ({len(w.robots)})" for w in waves))
