"""validate: load robot.yaml and say what it describes."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from robocore.commands.context import Options


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


def run(options: Options) -> None:
    """Validate robot.yaml; a ConfigError carries every problem (the task turns it into exit code 2)."""
    report = options.report
    if options.dry_run:
        report.notice(f"would validate {options.project_dir / 'robot.yaml'}")
        return
    project = options.load()
    robot = project.robot
    from robocore.commands.images import refuse_config_problems
    from robocore.config.loader import robot_warnings

    refuse_config_problems(project)  # what prepare-base and stage refuse for the robot's shape
    from robocore.commands.workspace import check_wheels_packages, debian_dependency_warnings

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
