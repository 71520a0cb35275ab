"""`robocore test` on real containers: colcon test of the template's packages in their staged images.

Controls: the passing run must find tests in every package (a run that found none would also
"pass"); a copy of the project with one wrong assertion added must fail, name that test and show
its message: ``test`` builds the edited package first, while ``test --no-build`` refuses the stale
build (the tests would run the old code); ``--packages-select`` must leave the other package's tests
unrun.
"""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from conftest import RobocoreCli

pytestmark = pytest.mark.docker

WRONG_TEST = '''\
from demo_talker.talker import greeting


def test_greeting_is_short() -> None:
    assert greeting(1) == "hello #1"
'''


def _row(stdout: str, package: str) -> list[str]:
    """The cells of ``package``'s row of the result table."""
    for line in stdout.splitlines():
        cells = [c for c in re.split(r"[\s│┃]+", line) if c]
        if package in cells:
            return cells
    raise AssertionError(f"no row for {package} in:\n{stdout}")


def test_the_template_packages_pass_with_their_tests_counted(demo_project: Path, run_robocore: RobocoreCli) -> None:
    proc = run_robocore(demo_project, "test")
    print(proc.stdout)
    assert _row(proc.stdout, "demo_talker") == ["talker", "demo_talker", "2", "0", "0", "0", "passed"]
    assert _row(proc.stdout, "demo_listener") == ["listener", "demo_listener", "2", "0", "0", "0", "passed"]
    for component, package in (("talker", "demo_talker"), ("listener", "demo_listener")):
        merged = ET.parse(demo_project / ".robocore/test-results" / component / f"{package}.xml").getroot()
        names = sorted(case.get("name", "") for case in merged.iter("testcase"))
        assert len(names) == 2 and all(n.startswith("test_") for n in names), names
        assert merged.get("failures") == "0" and merged.get("errors") == "0"
    as_json = run_robocore(demo_project, "test", "--json")
    doc = json.loads(as_json.stdout)
    assert doc["ok"] is True
    assert sorted((p["package"], p["tests"]) for c in doc["results"] for p in c["packages"]) == [
        ("demo_listener", 2), ("demo_talker", 2)]


def test_packages_select_runs_only_that_package(demo_project: Path, run_robocore: RobocoreCli) -> None:
    talker_result = demo_project / ".robocore/build/talker/build/demo_talker/pytest.xml"
    talker_result.unlink(missing_ok=True)
    proc = run_robocore(demo_project, "test", "--packages-select", "demo_listener")
    assert _row(proc.stdout, "demo_listener")[2] == "2"
    assert "demo_talker" not in proc.stdout and "demo_talker" not in proc.stderr
    results = sorted(p.relative_to(demo_project).as_posix()
                     for p in (demo_project / ".robocore/test-results").rglob("*.xml"))
    assert results == [".robocore/test-results/listener/demo_listener.xml"]
    assert not talker_result.exists()  # demo_talker's tests did not run
    unknown = run_robocore(demo_project, "test", "--packages-select", "nope", check=False)
    assert unknown.returncode == 2
    assert unknown.stderr.strip() == "error: unknown package 'nope' (known: demo_listener, demo_talker)"


def test_a_failing_test_fails_the_run_by_name_with_its_message(project_copies: Callable[..., Path],
                                                                run_robocore: RobocoreCli) -> None:
    root = project_copies("pkgtest")
    (root / "components/talker/src/demo_talker/test/test_wrong.py").write_text(WRONG_TEST)
    stale = run_robocore(root, "test", "--no-build", check=False)
    assert stale.returncode == 6, stale.stderr
    assert "component talker: the build is out of date (changed: demo_talker)" in stale.stderr
    proc = run_robocore(root, "test", check=False)  # builds the edited package first, then tests it
    print(proc.stdout, proc.stderr)
    assert proc.returncode == 9
    assert _row(proc.stdout, "demo_talker") == ["talker", "demo_talker", "3", "1", "0", "0", "FAILED"]
    assert _row(proc.stdout, "demo_listener")[-1] == "passed"
    lines = proc.stdout.splitlines()
    at = lines.index("FAILED demo_talker: demo_talker.test.test_wrong::test_greeting_is_short")
    assert "hello from talker #1" in lines[at + 1] and "hello #1" in lines[at + 1]
    assert proc.stderr.splitlines()[-1] == ("error: tests did not pass: 1 failed, 0 errored in demo_talker "
                                            "(JUnit XML in .robocore/test-results/)")
    merged = ET.parse(root / ".robocore/test-results/talker/demo_talker.xml").getroot()
    [failure] = [case for case in merged.iter("testcase") if case.find("failure") is not None]
    assert failure.get("name") == "test_greeting_is_short"
    # negative control: the same copy passes once the assertion is right
    (root / "components/talker/src/demo_talker/test/test_wrong.py").write_text(
        WRONG_TEST.replace('"hello #1"', '"hello from talker #1"'))
    fixed = run_robocore(root, "test", "--component", "talker")
    assert _row(fixed.stdout, "demo_talker") == ["talker", "demo_talker", "3", "0", "0", "0", "passed"]
