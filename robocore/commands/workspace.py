"""What the commands working on component workspaces share (stage, build, test): which components
a command works on and the source files of a workspace."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from pathlib import Path

from robocore.config.model import Component
from robocore.errors import UsageError
from robocore.files import refuse_links_leaving
from robocore.project import Project

#: Top-level folders of a workspace that hold colcon's output, not sources.
SKIP_WS_DIRS = frozenset({"build", "install", "log"})


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


def _skipped(ws: Path) -> Callable[[Path, str], bool]:
    """Which folders of workspace ``ws`` robocore never reads: VCS data, caches, hidden folders and the
    build outputs at its top."""
    from robocore.adapters.image_builder import SKIP_DIRS

    return lambda here, name: name in SKIP_DIRS or name.startswith(".") or (here == ws and name in SKIP_WS_DIRS)


def workspace_files(ws: Path) -> Iterator[tuple[str, Path]]:
    """Files of a workspace, without build outputs, VCS data, caches and COLCON_IGNOREd folders."""
    skipped = _skipped(ws)
    for dirpath, dirnames, filenames in os.walk(ws):
        here = Path(dirpath)
        if "COLCON_IGNORE" in filenames:
            dirnames[:] = []
            continue
        dirnames[:] = sorted(d for d in dirnames if not skipped(here, d))
        for name in sorted(filenames):
            if not name.endswith((".pyc", ".pyo")):
                yield (here / name).relative_to(ws).as_posix(), here / name


def check_workspace(project: Project, component: Component) -> Path:
    """The workspace folder of ``component``; UnsafePath if it, or a symlink in it, leads out of the project:
    stage copies from it and build mounts it, and what it builds is sent to robots."""
    assert component.folder is not None
    ws = project.root / component.folder
    refuse_links_leaving(ws, project.root, what=f"the workspace of component {component.name}", skip=_skipped(ws))
    return ws
