"""Helpers for the template tests: throw-away git repositories of robocore, and init with no surroundings.

``robocore init`` looks at where robocore was installed from (its source checkout, pip's
direct_url.json). Tests that are not about that choice run with both hidden (:func:`no_origin`),
so they give the same result on a developer's tagged checkout, a wheel install and CI.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

from robocore.adapters import copier_adapter, origin

REPO = Path(__file__).resolve().parents[1]
TEMPLATE = REPO / "template"
#: A git identity and no user/system git configuration, for every git and copier call of the tests.
GIT_ENV = {"GIT_AUTHOR_NAME": "t", "GIT_AUTHOR_EMAIL": "t@example.com", "GIT_COMMITTER_NAME": "t",
           "GIT_COMMITTER_EMAIL": "t@example.com", "GIT_CONFIG_GLOBAL": os.devnull, "GIT_CONFIG_NOSYSTEM": "1"}


def git(cwd: Path, *args: str) -> str:
    return subprocess.run(["git", *args], cwd=cwd, check=True, capture_output=True, text=True,
                          env={**os.environ, **GIT_ENV}, timeout=60).stdout


def source_files() -> list[str]:
    """robocore's files as git sees them: tracked, plus new ones that are not ignored."""
    out = git(REPO, "ls-files", "-z", "--cached", "--others", "--exclude-standard")
    return sorted({name for name in out.split("\0") if name and (REPO / name).is_file()})


def copy_sources(dest: Path) -> Path:
    """Copy robocore's source files into ``dest`` (a folder like a fresh checkout, without .git)."""
    for name in source_files():
        target = dest / name
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(REPO / name, target)
    return dest


def robocore_repository(dest: Path, tag: str = "v0.1.0") -> Path:
    """A git repository with robocore's files, one commit, tagged ``tag``."""
    copy_sources(dest)
    git(dest, "init", "-q", "-b", "main")
    git(dest, "add", "-A")
    git(dest, "commit", "-qm", f"robocore {tag}")
    git(dest, "tag", tag)
    return dest


def commit_all(repo: Path, message: str, tag: str | None = None) -> None:
    git(repo, "add", "-A")
    git(repo, "commit", "-qm", message)
    if tag:
        git(repo, "tag", tag)


def hide_origin(monkeypatch: pytest.MonkeyPatch) -> None:
    """Hide where robocore was installed from: init then renders the bundled template."""
    monkeypatch.setattr(origin, "installation", lambda distribution="robocore": origin.Installation())
    monkeypatch.setattr(origin, "source_checkout", lambda: None)
    monkeypatch.delenv(copier_adapter.TEMPLATE_ENV, raising=False)


def set_git_identity(monkeypatch: pytest.MonkeyPatch) -> None:
    """GIT_ENV in this process's environment (copier's own git calls read it)."""
    for key, value in GIT_ENV.items():
        monkeypatch.setenv(key, value)
