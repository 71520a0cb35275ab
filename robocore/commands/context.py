"""What every command receives from its task: the project folder and output flags."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from robocore.project import Project


@dataclass(frozen=True)
class Options:
    """Flags shared by all tasks."""

    project_dir: Path
    dry_run: bool = False
    quiet: bool = False
    json: bool = False

    def load(self) -> Project:
        """Load the project (raises ConfigError with every problem)."""
        return Project.load(self.project_dir)
