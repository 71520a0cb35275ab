"""Write the per-host compose files (``.robocore/compose/<host>.yaml``) from the container specs."""

from __future__ import annotations

from pathlib import Path

from robocore.project import Project


def write_compose_files(project: Project) -> list[Path]:
    """Write one compose file per host; return their paths. (Filled by the deploy work, issue #4.)"""
    return []
