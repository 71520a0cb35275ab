"""A robot project made with ``copier copy`` tests itself as its README says: its own nox sessions.

``nox --no-venv -s validate build unit graph`` in a fresh project on the wheels base: validate
robot.yaml, build the images and workspaces, run the packages' own tests in their images, then
the graph tests through robocore's pytest plugin. The control: a package test that expects a
wrong value makes ``unit`` fail, naming the test.
"""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest
from deploy_helpers import output_tails, run_nox

pytestmark = pytest.mark.docker

TEMPLATE = Path(__file__).resolve().parents[1] / "template"
#: The demo project's name: its images (robocore-it-demo-*) are the warm cache these runs reuse.
NAME = "robocore-it-demo"


@pytest.fixture(scope="module")
def copied_project(docker_client: object, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """``copier copy template/ DIR --defaults -d base_kind=wheels``, as a robot team starts."""
    from copier import run_copy

    root = tmp_path_factory.mktemp("copier") / NAME
    run_copy(str(TEMPLATE), str(root), data={"base_kind": "wheels"}, defaults=True, unsafe=True, quiet=True)
    yield root
    shutil.rmtree(root, ignore_errors=True)


def test_the_generated_projects_nox_sessions_pass(copied_project: Path) -> None:
    proc = run_nox(copied_project, "validate", "build", "unit", "graph")
    assert proc.returncode == 0, output_tails(proc)
    text = proc.stdout + proc.stderr
    for session in ("validate", "build", "unit", "graph"):
        assert f"Session {session} was successful" in text, output_tails(proc)
    assert "passed" in text and "failed" not in text.split("Session graph")[0].split("Running session graph")[-1]


def test_a_failing_package_test_fails_the_unit_session(copied_project: Path, tmp_path: Path) -> None:
    root = tmp_path / NAME
    shutil.copytree(copied_project, root, symlinks=True)
    tests = sorted((root / "components" / "talker").rglob("test_*.py"))
    assert tests, "the template's talker package has no tests"
    (tests[0].parent / "test_wrong_on_purpose.py").write_text(
        "def test_expects_a_wrong_value():\n    assert 1 + 1 == 3, 'wrong on purpose'\n")
    proc = run_nox(root, "build", "unit")
    assert proc.returncode != 0, output_tails(proc)
    assert "Session build was successful" in proc.stderr, output_tails(proc)
    assert "test_expects_a_wrong_value" in proc.stdout + proc.stderr, output_tails(proc)
