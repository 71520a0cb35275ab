"""validate: load robot.yaml and say what it describes."""

from __future__ import annotations

from robocore.commands.context import Options
from robocore.ui import console


def run(options: Options) -> None:
    """Validate robot.yaml; a ConfigError carries every problem (the task turns it into exit code 2)."""
    out = console()
    if options.dry_run:
        out.print(f"would validate {options.project_dir / 'robot.yaml'}", soft_wrap=True, markup=False)
        return
    project = options.load()
    robot = project.robot
    from robocore.config.loader import located, robot_warnings
    from robocore.plan.dockerfiles import wheels_problems

    found = wheels_problems(robot)
    if found:
        raise located(project.robot_file, found)
    from robocore.commands.workspace import check_wheels_packages

    check_wheels_packages(project)
    for warning in robot_warnings(project.robot_file, robot, project.root):
        out.print(str(warning), soft_wrap=True, markup=False)
    lines = [
        f"{project.robot_file}: ok — ROS 2 {robot.ros_distro.value}, {len(robot.hosts)} host(s), "
        f"{len(robot.components)} component(s), base {robot.base.kind.value}"
    ]
    by_host: dict[str, list[str]] = {}
    for comp in robot.components:
        by_host.setdefault(comp.runs_on, []).append(comp.name)
    for host in robot.hosts:
        names = ", ".join(by_host.get(host.name, [])) or "no components"
        lines.append(f"  {host.name} ({host.ip}, {host.arch.value}, docker via {host.access.value}): {names}")
    servers = ", ".join(f"{s.host}:{s.port}" for s in robot.discovery_servers)
    lines.append(f"  discovery server: {servers}")
    if not options.quiet:
        for line in lines:
            out.print(line, soft_wrap=True, markup=False)
