"""Unit-test fixtures: throw-away robot projects in tmp_path (no Docker)."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path

import pytest

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
