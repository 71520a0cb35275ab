"""What the commands working on component workspaces share (stage, build, test): which components
a command works on, the source files of a workspace, and the dev machine's Docker client that
builds images and runs the colcon containers."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from robocore.config.model import Component
from robocore.errors import UsageError
from robocore.project import Project

if TYPE_CHECKING:
    import docker

#: Top-level folders of a workspace that hold colcon's output, not sources.
SKIP_WS_DIRS = frozenset({"build", "install", "log"})


def local_docker() -> docker.DockerClient:
    """The dev machine's Docker daemon, with a timeout long enough for image builds and colcon runs."""
    from robocore.adapters.docker_hosts import local_client

    return local_client(timeout=3600)


def selected_components(project: Project, component: str | None) -> list[Component]:
    """The components built from source that a command works on: ``component`` only, or all of them.

    A component named on the command line that uses a pre-built image is a UsageError.
    """
    if component:
        comp = project.component(component)
        if comp.image is not None:
            raise UsageError(f"component {component!r} uses the pre-built image {comp.image}; "
                             "nothing to stage, build or test")
        return [comp]
    return [c for c in project.robot.components if c.image is None]


def workspace_files(ws: Path) -> Iterator[tuple[str, Path]]:
    """Files of a workspace, without build outputs, VCS data, caches and COLCON_IGNOREd folders."""
    from robocore.adapters.image_builder import SKIP_DIRS

    for dirpath, dirnames, filenames in os.walk(ws):
        here = Path(dirpath)
        if "COLCON_IGNORE" in filenames:
            dirnames[:] = []
            continue
        dirnames[:] = sorted(d for d in dirnames if d not in SKIP_DIRS and not (here == ws and d in SKIP_WS_DIRS)
                             and not d.startswith("."))
        for name in sorted(filenames):
            if not name.endswith((".pyc", ".pyo")):
                yield (here / name).relative_to(ws).as_posix(), here / name
