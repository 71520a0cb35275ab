"""Shared fixtures of the Docker integration suites.

- ``docker_client``: a docker-py client of the local daemon; FAILS (never skips) without one.
- ``demo_project``: one session-wide robot project (``robocore init --defaults --base wheels``)
  taken through ``prepare-base``, ``stage`` and ``build``. Its folder name is fixed, so its
  images (``robocore-it-demo-*``) survive between runs and a rerun is a cheap no-op thanks to the
  content-hash labels; the images are the cache and are kept on purpose.
- ``run_robocore``: run ``python -m robocore -p PROJECT ...`` and return the completed process.

Containers created by tests must be removed by the tests themselves; name them with a
``robocore-it-`` prefix so a leftover is easy to spot.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

os.environ.setdefault("TESTCONTAINERS_RYUK_DISABLED", "true")

DEMO_NAME = "robocore-it-demo"
RunRobocore = Callable[..., "subprocess.CompletedProcess[str]"]


def _robocore(
    project: Path | None, *args: str, check: bool = True, timeout: float = 1800
) -> subprocess.CompletedProcess[str]:
    argv = [sys.executable, "-m", "robocore"]
    if project is not None:
        argv += ["-p", str(project)]
    argv += list(args)
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=timeout)
    if check and proc.returncode != 0:
        pytest.fail(
            f"`robocore {' '.join(args)}` exited {proc.returncode}\n--- stdout\n{proc.stdout[-4000:]}\n"
            f"--- stderr\n{proc.stderr[-4000:]}",
            pytrace=False,
        )
    return proc


@pytest.fixture(scope="session")
def run_robocore() -> RunRobocore:
    """``run_robocore(project, *args, check=True)`` runs the robocore CLI in a subprocess."""
    return _robocore


@pytest.fixture(scope="session")
def docker_client() -> Iterator[object]:
    """A client of the local Docker daemon. Fails loudly when there is none."""
    try:
        import docker

        client = docker.from_env(timeout=300)
        client.ping()
    except Exception as exc:
        pytest.fail(
            f"the integration suites need a reachable Docker daemon (DOCKER_HOST or /var/run/docker.sock): {exc}",
            pytrace=False,
        )
    yield client
    client.close()


def make_demo_project(parent: Path, name: str = DEMO_NAME) -> Path:
    """``robocore init PARENT/NAME --defaults --base wheels``: the template project on the wheels base."""
    root = parent / name
    if root.exists():
        shutil.rmtree(root)
    _robocore(None, "init", str(root), "--defaults", "--base", "wheels")
    return root


@pytest.fixture(scope="session")
def demo_project(docker_client: object) -> Iterator[Path]:
    """The template project (wheels base) after prepare-base, stage and build; returns its folder."""
    parent = Path(tempfile.mkdtemp(prefix="robocore-it-"))
    root = make_demo_project(parent)
    for step in ("prepare-base", "stage", "build"):
        _robocore(root, step, "--quiet")
    yield root
    shutil.rmtree(parent, ignore_errors=True)
