"""validate: load robot.yaml and say what it describes."""

from __future__ import annotations

from robocore.commands.context import Options
from robocore.ui import console


def run(options: Options) -> None:
    """Validate robot.yaml; a ConfigError carries every problem."""
    if options.dry_run:
        console().print(f"would validate {options.project_dir / 'robot.yaml'}")
        return
    project = options.load()
    robot = project.robot
    console().print(
        f"{project.robot_file}: ok — ROS 2 {robot.ros_distro.value}, {len(robot.hosts)} host(s), "
        f"{len(robot.components)} component(s), base {robot.base.kind.value}"
    )
