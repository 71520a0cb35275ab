"""What the commands working on component workspaces share (stage, build, test): which components
a command works on and the source files of a workspace."""

from __future__ import annotations

import os
import stat
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from robocore.config.model import Component
from robocore.errors import ConfigError, Problem, UnsafePath, UsageError
from robocore.files import read_project_file, refuse_links_leaving
from robocore.project import Project

if TYPE_CHECKING:
    from robocore.plan.cmake_packages import Manifest

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


#: A folder holding one of these files is skipped by colcon (colcon-core's marker and colcon-ros' two).
IGNORE_MARKERS = frozenset({"COLCON_IGNORE", "AMENT_IGNORE", "CATKIN_IGNORE"})


def workspace_files(ws: Path) -> Iterator[tuple[str, Path]]:
    """Files of a workspace, without build outputs, VCS data, caches and the folders colcon ignores (a
    ``COLCON_IGNORE``, ``AMENT_IGNORE`` or ``CATKIN_IGNORE`` file in them): what colcon builds, nothing else."""
    skipped = _skipped(ws)
    for dirpath, dirnames, filenames in os.walk(ws):
        here = Path(dirpath)
        if not IGNORE_MARKERS.isdisjoint(filenames):
            dirnames[:] = []
            continue
        dirnames[:] = sorted(d for d in dirnames if not skipped(here, d))
        for name in sorted(filenames):
            if not name.endswith((".pyc", ".pyo")):
                mode = os.lstat(here / name).st_mode
                if not (stat.S_ISREG(mode) or stat.S_ISLNK(mode)):  # a FIFO would block a read for ever
                    raise UnsafePath(f"{here / name}: is not a regular file (a FIFO, socket or device); a workspace "
                                     "holds files and links only", hint=f"remove {here / name}")
                yield (here / name).relative_to(ws).as_posix(), here / name


def check_workspace(project: Project, component: Component) -> Path:
    """The workspace folder of ``component``; UnsafePath if it, or a symlink in it, leads out of the project:
    stage copies from it and build mounts it, and what it builds is sent to robots."""
    assert component.folder is not None
    ws = project.root / component.folder
    refuse_links_leaving(ws, project.root, what=f"the workspace of component {component.name}", skip=_skipped(ws))
    return ws


def package_manifests(folder: Path, project_root: Path) -> list[Manifest]:
    """The package.xml files of a source tree (a workspace, a common package, a fetched repository), read;
    paths in messages are relative to ``project_root`` when under it."""
    from robocore.plan.cmake_packages import read_manifest

    files = {rel for rel, _ in workspace_files(folder)}
    found: list[Manifest] = []
    for rel in sorted(files):
        root, _, name = rel.rpartition("/")
        if name != "package.xml":
            continue
        path = folder / rel
        shown = path.relative_to(project_root).as_posix() if path.is_relative_to(project_root) else str(path)
        cmakelists = f"{root}/CMakeLists.txt" if root else "CMakeLists.txt"
        text = read_project_file(path, project_root, what="package.xml").decode("utf-8", errors="replace")
        found.append(read_manifest(text, shown, has_cmakelists=cmakelists in files))
    return found


def wheels_cmake_packages(project: Project, sources: Sequence[Path]) -> list[str]:
    """The packages of ``sources`` that colcon builds with CMake, when the base is ``wheels`` (which then
    adds the CMake tool chain to the image they are built in); empty on other bases.

    A package the wheels base cannot build (one depending on rclcpp) is a ConfigError, one line each.
    """
    from robocore.config.model import BaseKind
    from robocore.plan import cmake_packages

    if project.robot.base.kind is not BaseKind.wheels:
        return []
    manifests = [m for source in sources for m in package_manifests(source, project.root)]
    refusals = cmake_packages.wheels_refusals(project.robot.ros_distro.value, manifests)
    if refusals:
        raise ConfigError([Problem(r.file, r.line, r.key, r.message) for r in refusals])
    return cmake_packages.cmake_packages(manifests)


def check_wheels_packages(project: Project) -> None:
    """Every package the wheels base cannot build, in component workspaces and local common packages, as
    one ConfigError (a line each); nothing on other bases. Folders that do not exist yet are skipped."""
    from robocore.config.model import BaseKind

    if project.robot.base.kind is not BaseKind.wheels:
        return
    folders = [project.root / c.folder for c in project.robot.components if c.folder and c.image is None]
    folders += [project.root / (p.folder or p.name) for p in project.robot.common_packages if not p.repo]
    problems: list[Problem] = []
    for folder in folders:
        if folder.is_dir():
            try:
                wheels_cmake_packages(project, [folder])
            except ConfigError as exc:
                problems += exc.problems
    if problems:
        raise ConfigError(problems)


def debian_dependency_warnings(project: Project) -> list[Problem]:
    """On the debian base, one warning per package.xml dependency that nothing resolves (no rosdep there:
    the base's ROS packages, the project's own packages or the component's apt_packages must); none on
    other bases. Folders that do not exist yet are skipped."""
    from robocore.config.model import BaseKind
    from robocore.plan import debian_packages

    robot = project.robot
    if robot.base.kind is not BaseKind.debian:
        return []
    common = [project.root / (p.folder or p.name) for p in robot.common_packages if not p.repo]
    common_manifests = [m for folder in common if folder.is_dir() for m in package_manifests(folder, project.root)]
    provided = {m.name for m in common_manifests} | {p.name for p in robot.common_packages}
    found = debian_packages.unresolved(common_manifests, provided=provided, apt=())
    for comp in robot.components:
        ws = project.root / comp.folder if comp.folder and comp.image is None else None
        own = package_manifests(ws, project.root) if ws is not None and ws.is_dir() else []
        found += debian_packages.unresolved(own, provided=provided | {m.name for m in own}, apt=comp.apt_packages)
    return [Problem(u.file, u.line, u.key, u.message, severity="warning") for u in found]
