"""What every command receives from its task: the project folder, the output flags and the reporter."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

from robocore.commands.support.reporting import Reporter
from robocore.project import Project

#: What a dry run says where the plan needs an answer only a Docker daemon or a host could give.
DRY_RUN_UNKNOWN = "unknown (dry run: not contacted)"


@dataclass(frozen=True)
class Options:
    """Flags shared by all tasks."""

    project_dir: Path
    dry_run: bool = False
    quiet: bool = False
    json: bool = False
    #: The whole command line, when a CLI runs the task: it says which remote steps follow (ssh warm-up).
    argv: tuple[str, ...] = ()
    #: The task's name, as the JSON document names it.
    task: str = ""

    @cached_property
    def report(self) -> Reporter:
        """Where this task's output goes (one reporter per task run)."""
        return Reporter(self.task, json=self.json, quiet=self.quiet)

    def load(self) -> Project:
        """Load the project (raises ConfigError with every problem)."""
        project = Project.load(self.project_dir)
        if not self.dry_run and self.task != "validate":  # validate writes nothing; a dry run neither
            project.check_state_links()
        if not self.dry_run:
            warm_remote_hosts(project, list(self.argv))
        return project


def warm_remote_hosts(project: Project, argv: list[str]) -> None:
    """When ``argv`` names a step that uses the robot hosts (and is not a dry run): open the ssh
    connections to the hosts that run something, once per process, and record them for the next
    command (see :mod:`robocore.commands.support.warmup`); when it names a step that uses their Docker
    daemons, open those connections too, for the step to take."""
    from robocore.commands.support import warmup
    from robocore.config.model import DockerAccess

    if not warmup.wants_remote(argv):
        return
    endpoints = [warmup.Endpoint(h.name, h.user, h.ip, h.ssh_port) for h in project.robot.hosts_in_use()
                 if h.access is DockerAccess.ssh]
    warmup.warm_loaded(project.root, endpoints, argv)
    if warmup.wants_docker(argv):
        from robocore.commands.support.hosts import prefetch_connections

        prefetch_connections(project)
