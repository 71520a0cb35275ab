"""``.ci/run`` stops itself before CI's limit, and the stopped run still shows its progress and slowest tests.

The real ``.ci/run`` and ``noxfile.py`` run in a copy of the repository's layout whose ``scripts/test`` is a
stand-in running nox's integration session, as CI runs it (in the noxfile's lanes), on two small tests: one
passes, one sleeps past a 30-second limit (long enough for nox, pytest and its lanes' workers to start on a loaded
machine: 4 s stopped a busy one while pytest was still importing, and 15 s one whose two workers had not yet
collected).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent

STAND_IN_TEST = """#!/usr/bin/env bash
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
exec nox --no-venv -s integration
"""

SUITE = """
import time
import pytest


@pytest.fixture
def slow_teardown():
    yield
    time.sleep(1.0)  # longer than nox's own 0.3 s grace: the summary must still be printed
    print("teardown finished")


def test_quick():
    pass


def test_stuck(slow_teardown):
    time.sleep(600)
"""


def make_copy(tmp_path: Path) -> Path:
    repo = tmp_path / "repo"
    (repo / ".ci").mkdir(parents=True)
    (repo / "scripts").mkdir()
    (repo / "integration").mkdir()
    shutil.copy2(ROOT / ".ci" / "run", repo / ".ci" / "run")
    shutil.copy2(ROOT / "noxfile.py", repo / "noxfile.py")
    (repo / "scripts" / "test").write_text(STAND_IN_TEST)
    (repo / "scripts" / "test").chmod(0o755)
    (repo / "integration" / "test_limit.py").write_text(SUITE)
    return repo


def ci_env(**extra: str) -> dict[str, str]:
    """The environment of CI's run: the lanes the noxfile sets (not this shell's ``ROBOCORE_IT_LANES``)."""
    env = {**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ['PATH']}", **extra}
    env.pop("ROBOCORE_IT_LANES", None)
    return env


def test_ci_run_stops_at_its_limit_with_progress_and_durations(tmp_path: Path) -> None:
    repo = make_copy(tmp_path)
    env = ci_env(ROBOCORE_CI_LIMIT="30s", ROBOCORE_CI_GRACE="60s", TERM="dumb")
    done = subprocess.run(["bash", str(repo / ".ci" / "run")], cwd=tmp_path, env=env, stdin=subprocess.DEVNULL,
                          capture_output=True, text=True, timeout=180)
    output = done.stdout + done.stderr
    assert done.returncode == 124, output
    assert "ci: stopped after 30s" in done.stderr
    assert "KeyboardInterrupt" in output  # where the run was when it stopped
    assert "slowest 60 durations" in output  # --durations=60 of the integration session
    assert "1 passed" in output  # the progress so far
    assert "teardown finished" in output or "test_stuck" in output


def test_ci_run_passes_the_exit_code_of_a_run_within_its_limit(tmp_path: Path) -> None:
    repo = make_copy(tmp_path)
    (repo / "integration" / "test_limit.py").write_text("def test_quick():\n    pass\n")
    env = ci_env(ROBOCORE_CI_LIMIT="100s")
    done = subprocess.run(["bash", str(repo / ".ci" / "run")], cwd=tmp_path, env=env, stdin=subprocess.DEVNULL,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "1 passed" in done.stdout
    assert "ci: stopped" not in done.stderr
