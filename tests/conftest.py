"""Unit-test fixtures: throw-away robot projects in tmp_path (no Docker)."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path

import pytest
from hypothesis import settings

from robocore.project import Project

# Hypothesis' per-example deadline (200 ms) is a timing assertion: on a loaded machine it fails tests whose
# behaviour is right. Speed is measured in bench/, so no property test here has a deadline.
settings.register_profile("robocore", deadline=None)
settings.load_profile("robocore")

MakeProject = Callable[..., Path]


def write_project(root: Path, text: str, folders: Iterable[str] = ()) -> Path:
    """Create ``root`` with ``robot.yaml`` = ``text`` and the given (relative) folders."""
    root.mkdir(parents=True, exist_ok=True)
    (root / "robot.yaml").write_text(text, encoding="utf-8")
    for folder in folders:
        (root / folder).mkdir(parents=True, exist_ok=True)
    return root


@pytest.fixture
def make_project(tmp_path: Path) -> MakeProject:
    """``make_project(text, folders=(), name="robot")`` -> the project folder, inside tmp_path."""

    def make(text: str, folders: Iterable[str] = (), name: str = "robot") -> Path:
        return write_project(tmp_path / name, text, folders)

    return make


def built_project(root: Path, text: str, components: Iterable[str] = ("talker", "listener")) -> Project:
    """A project at ``root`` as after stage and build: robot.yaml = ``text``, one package per component's
    workspace (``components/<c>/src/<c>_pkg``), compose files and DDS profiles written, install trees made."""
    from robocore.commands.support.composefiles import write_compose_files

    for comp in components:
        pkg = root / "components" / comp / "src" / f"{comp}_pkg"
        pkg.mkdir(parents=True)
        (pkg / "package.xml").write_text(f"<package><name>{comp}_pkg</name></package>")
    (root / "robot.yaml").write_text(text)
    project = Project.load(root)
    write_compose_files(project)
    for comp in components:
        (project.build_dir(comp) / "install").mkdir(parents=True)
    return project
