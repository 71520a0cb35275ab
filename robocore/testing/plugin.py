"""The pytest plugin (entry point ``pytest11``): the ``robot`` fixture for a robot project's graph tests.

Loaded by every pytest run where robocore is installed, so importing it costs nothing: Docker,
testcontainers and rclpy are imported only when a test asks for ``robot``.
"""

from __future__ import annotations

import contextlib
import signal
from collections.abc import Generator, Iterator
from pathlib import Path
from types import FrameType
from typing import Any

import pytest

from robocore.errors import RobocoreError
from robocore.files import ROBOT_FILE

_RUN = pytest.StashKey["Any"]()


def pytest_addoption(parser: pytest.Parser) -> None:
    """``--robocore-project DIR``."""
    group = parser.getgroup("robocore", "robocore robot tests")
    group.addoption("--robocore-project", metavar="DIR", default=None,
                    help="robot project whose robot.yaml the robot fixture brings up "
                         "(default: the nearest robot.yaml above the current folder)")


def pytest_configure(config: pytest.Config) -> None:
    """Register the ``robot`` marker's description."""
    config.addinivalue_line("markers", "robot: the test uses a robot project brought up by robocore")
    # rclpy's message parser (lark) imports modules Python 3.11 deprecates: noise in every robot test's summary
    for module in ("sre_parse", "sre_constants"):
        config.addinivalue_line("filterwarnings", f"ignore:module '{module}' is deprecated:DeprecationWarning")


def find_project(start: Path) -> Path | None:
    """The folder of the robot.yaml nearest above ``start`` (``start`` included), or None."""
    for folder in (start, *start.parents):
        if (folder / ROBOT_FILE).is_file():
            return folder
    return None


def _project_dir(config: pytest.Config) -> Path:
    given = config.getoption("--robocore-project")
    if given:
        path = Path(given).expanduser().resolve()
        if not (path / ROBOT_FILE).is_file():
            raise pytest.UsageError(f"--robocore-project {given}: no {ROBOT_FILE} in {path}")
        return path
    found = find_project(Path.cwd().resolve()) or find_project(config.rootpath)
    if found is None:
        raise pytest.UsageError(f"the robot fixture found no {ROBOT_FILE} above {Path.cwd()}: "
                                "run pytest inside a robot project or pass --robocore-project DIR")
    return found


@contextlib.contextmanager
def _sigterm_as_interrupt() -> Iterator[None]:
    """Turn SIGTERM (a cancelled CI job) into KeyboardInterrupt, so that the run is taken down."""
    def interrupt(signum: int, frame: FrameType | None) -> None:
        raise KeyboardInterrupt

    try:
        previous = signal.signal(signal.SIGTERM, interrupt)
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


@pytest.fixture(scope="session")
def robot(request: pytest.FixtureRequest) -> Generator[Any, None, None]:
    """The robot project, built and running isolated on the local Docker daemon, with ``robot.graph``."""
    from robocore.testing.bringup import bring_up

    config = request.config
    project = _project_dir(config)
    with _sigterm_as_interrupt():
        try:
            run = bring_up(project)
        except RobocoreError as error:
            request.session.shouldstop = "robocore: the robot could not be brought up"
            pytest.fail("robocore: " + "\n".join(error.lines()), pytrace=False)
        config.stash[_RUN] = run
        try:
            yield run
        finally:
            run.close()


@pytest.fixture(autouse=True)
def _robot_components_running(request: pytest.FixtureRequest) -> Generator[None, None, None]:
    """Around each test that uses ``robot``: before, undo any fault and start again whatever an earlier test
    stopped; after, undo the test's faults (pass or fail), so that none outlives its test."""
    if "robot" not in request.fixturenames:
        yield
        return
    from robocore.testing.bringup import RobotUnderTest

    run = request.getfixturevalue("robot")
    if not isinstance(run, RobotUnderTest):  # a project's own fixture of that name
        yield
        return
    run.ensure_running()
    yield
    run.undo_faults()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Generator[None, Any, None]:
    """A failed test's report gets every component's last log lines and the graph at that moment."""
    outcome = yield
    report = outcome.get_result()
    if not report.failed or call.when == "teardown":
        return
    run = item.config.stash.get(_RUN, None)
    if run is None or "robot" not in getattr(item, "fixturenames", ()):
        return
    with contextlib.suppress(Exception):
        if in_force := run.faults_in_force():
            report.sections.append(("robocore: faults in force", "\n".join(in_force)))
    with contextlib.suppress(Exception):
        report.sections.append(("robocore: components and graph", run.report()))


def pytest_terminal_summary(terminalreporter: Any, config: pytest.Config) -> None:
    """How long the robot took to come up, and what the run noticed (leftovers removed, packages not loadable)."""
    run = config.stash.get(_RUN, None)
    if run is None:
        return
    timings = run.timings
    if timings:
        terminalreporter.write_line(
            f"robocore: robot up in {timings['total']:.1f} s (builds checked in {timings['build']:.1f} s, "
            f"containers and graph {timings['start']:.1f} s)")
    for note in run.notes:
        terminalreporter.write_line(f"robocore: {note}")


def pytest_unconfigure(config: pytest.Config) -> None:
    """Take the run down even when the session ended without fixture teardown (Ctrl-C)."""
    run = config.stash.get(_RUN, None)
    if run is not None:
        run.close()
