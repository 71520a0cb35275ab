"""What every command receives from its task: the project folder and output flags."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

from robocore.project import Project

#: Steps that talk to the robot hosts over ssh. When the command line names one (``build sync run``),
#: loading the project opens those connections in the background, so the handshake overlaps with the
#: steps before it.
REMOTE_STEPS = frozenset({"sync", "run", "status", "logs", "connect", "doctor", "down", "rollback"})
_warmed: set[Path] = set()


@dataclass(frozen=True)
class Options:
    """Flags shared by all tasks."""

    project_dir: Path
    dry_run: bool = False
    quiet: bool = False
    json: bool = False

    def load(self) -> Project:
        """Load the project (raises ConfigError with every problem)."""
        project = Project.load(self.project_dir)
        if not self.dry_run:
            warm_remote_hosts(project, sys.argv[1:])
        return project


def warm_remote_hosts(project: Project, argv: list[str]) -> None:
    """Open ssh connections to the hosts that run something, once per process, when ``argv`` names a
    step that will use them (and is not a dry run)."""
    if project.root in _warmed or not REMOTE_STEPS & set(argv) or "--dry-run" in argv:
        return
    _warmed.add(project.root)
    from robocore.adapters import ssh
    from robocore.config.model import DockerAccess

    used = {c.runs_on for c in project.robot.components} | {s.host for s in project.robot.discovery_servers}
    for host in project.robot.hosts:
        if host.access is DockerAccess.ssh and host.name in used:
            ssh.warm(host)
