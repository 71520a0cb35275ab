"""Shared fixtures of the Docker integration suites.

The robocore CLI
- ``run_robocore`` (session): the one way the suites run the CLI, ``python -m robocore -p PROJECT
  ...`` in a subprocess (:class:`RobocoreCli`): in the foreground (returns the completed process;
  fails the test with the command, exit code and output tails when asked to check), left running
  (``.start``), or on a pseudo-terminal (``.in_terminal``).

Docker, projects and robot hosts
- ``docker_client`` (session): a docker-py client of the local daemon; FAILS (never skips) without one.
- ``new_demo_project`` (session): ``robocore init DIR/robocore-it-demo --defaults --base wheels`` in a
  new temporary folder; every such folder is removed at the end of the session.
- ``demo_project`` (session): one of those taken through ``prepare-base``, ``stage`` and ``build``.
  Its folder name is fixed, so its images (``robocore-it-demo-*``) survive between runs and a rerun
  is a cheap no-op thanks to the content-hash labels; the images are the cache and are kept on purpose.
- ``project_copies`` (function): throw-away copies of the demo project; their containers are removed.
- ``robot_run`` (function): a project brought up by the pytest plugin's machinery; closed afterwards.
- ``robot_fleets`` (module) and ``fleet`` (module): Docker-in-Docker robot hosts reached over ssh://
  (bench/robot_host/); removed after the module's last test.
- ``arm64_images`` (session): waits for the arm64 suites' images, made in the background
  (:mod:`arm64_project`) while the other suites run; those suites (:data:`lanes.ARM64_IMAGES`) run late.

What a test creates is removed by a fixture, pass or fail
- ``tracked_containers``: containers a test starts itself;
- ``restore``: files and folders of a shared project a test edits, put back afterwards;
- ``background``: processes left running (and ``run_robocore.start``): their process groups are
  killed when the test ends.

Name containers with a ``robocore-it-`` prefix so that a leftover is easy to spot.
"""

from __future__ import annotations

import contextlib
import os
import pty
import select
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

import arm64_project
import ci_times
import lanes
import pytest
from deploy_helpers import copy_project, output_tails, remove_project_containers, remove_test_runs
from robot_host.build import ensure_image
from robot_host.hosts import RobotFleet

os.environ.setdefault("TESTCONTAINERS_RYUK_DISABLED", "true")

DEMO_NAME = "robocore-it-demo"
#: Environment changes of a CLI run: variables set on top of this process's environment, None removes one.
Env = Mapping[str, "str | None"]

#: Processes started with :func:`start_process` (``background``, ``run_robocore.start``), oldest first.
_STARTED: list[subprocess.Popen[str]] = []


#: The background run of :mod:`arm64_project` this session started, if any.
_IMAGES_AHEAD: list[subprocess.Popen[bytes]] = []


def pytest_configure(config: pytest.Config) -> None:
    """The per-module time table (:mod:`ci_times`) and the ``quiet`` marker (:mod:`lanes`)."""
    config.addinivalue_line("markers", "quiet: a timed test: no other lane builds while it runs (integration/lanes.py)")
    ci_times.register(config)


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Each module's tests join its group (:func:`lanes.group_of`: the xdist group a lane takes whole), and the
    groups are put in :mod:`lanes`' queue order (a stable sort: the tests of a module keep their order). The arm64
    suites go last, so that their images are made in the background while the others run."""
    ranks = {}
    _TIMED_MODULES.update(item.path.name for item in items if item.get_closest_marker("quiet") is not None)
    for item in items:
        rank, group = lanes.group_of(item.path.name)
        ranks[item.nodeid] = rank
        item.add_marker(pytest.mark.xdist_group(group))
    items.sort(key=lambda item: ranks[item.nodeid])


#: The modules with quiet tests (:func:`lanes.hold_module`).
_TIMED_MODULES: set[str] = set()
#: What this lane holds for the module under way, taken at its first test's set-up, let go of after its last
#: teardown, last taken first: :func:`lanes.hold_alone`'s, the arm64 project's lock while one of
#: :data:`lanes.ARM64_PROJECT` runs, then :func:`lanes.hold_module`'s (descriptors).
_MODULE_HOLDS: list[int] = []
#: The module :data:`_MODULE_HOLDS` is for.
_HELD_FOR: list[Path] = []


@pytest.hookimpl(wrapper=True)
def pytest_runtest_setup(item: pytest.Item) -> Iterator[None]:
    """Every test's set-up holds the machine shared: it waits while another lane runs a quiet test's body. The first
    test of a module first takes what the module holds to its end (before the machine's lock): its share of the
    machine (:func:`lanes.hold_alone`: a module of :data:`lanes.ALONE` runs with no other), the arm64 project for a
    module of :data:`lanes.ARM64_PROJECT`, then :func:`lanes.hold_module`'s lock (a module with quiet tests and the
    Swarm suite never run side by side). The seconds each phase waited go to the time table
    (:func:`ci_times.held_back`): pytest counts them in the phase."""
    asked = time.monotonic()
    if [item.path] != _HELD_FOR:
        _let_go_of_module()
        _HELD_FOR.append(item.path)
        _MODULE_HOLDS.append(lanes.hold_alone(item.path.name))
        if item.path.name in lanes.ARM64_PROJECT:
            _MODULE_HOLDS.append(lanes.hold_project("robocore-it-arm64"))
        held = lanes.hold_module(item.path.name, item.path.name in _TIMED_MODULES)
        if held is not None:
            _MODULE_HOLDS.append(held)
    with lanes.working():
        ci_times.held_back(item, "setup", time.monotonic() - asked)
        return (yield)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item: pytest.Item) -> Iterator[None]:
    """A quiet test's body runs while every other lane stands still between two phases (:func:`lanes.quiet`), but
    for its untimed stretches (:func:`lanes.untimed`); any other body holds the machine shared. How long the body
    held the machine alone goes to the time table (:func:`ci_times.held_alone`)."""
    asked = time.monotonic()
    alone = lanes.alone_seconds()
    try:
        with lanes.quiet() if item.get_closest_marker("quiet") is not None else lanes.working():
            ci_times.held_back(item, "call", time.monotonic() - asked)
            return (yield)
    finally:
        ci_times.held_alone(item, lanes.alone_seconds() - alone)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_teardown(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    """Every test's teardown holds the machine shared, as its set-up does; after a module's last test (its module
    fixtures torn down), what the module held to its end goes."""
    asked = time.monotonic()
    try:
        with lanes.working():
            ci_times.held_back(item, "teardown", time.monotonic() - asked)
            return (yield)
    finally:
        if nextitem is None or nextitem.path != item.path:
            _let_go_of_module()


def _let_go_of_module() -> None:
    """Let go of what this lane holds for the module it ran last, last taken first."""
    while _MODULE_HOLDS:
        lanes.let_go(_MODULE_HOLDS.pop())
    _HELD_FOR.clear()


def pytest_collection_finish(session: pytest.Session) -> None:
    """Starts making the arm64 suites' images in the background when they are to run and nobody is making them
    (``scripts/test`` starts that before the unit tests)."""
    if session.config.option.collectonly:  # listing the tests (tests/test_proofs.py) makes no image
        return
    if any(item.path.name in lanes.ARM64_IMAGES for item in session.items) and not arm64_project.is_running():
        _IMAGES_AHEAD.append(arm64_project.start())


def pytest_xdist_node_collection_finished(node: Any, ids: list[str]) -> None:
    """Refuses a session whose lanes would not take each group whole (the modules of a group share a project:
    run in two lanes at once, they would remove each other's containers). xdist's ``--dist loadgroup`` marks a
    group in its tests' node IDs; pytest 9.2 drops that mark (pytest-xdist#1386) and the session would go on as
    ``--dist load``, one test here, the next there."""
    ungrouped = [nodeid for nodeid in ids if "@" not in nodeid.rpartition("]")[2]]
    if node.config.getvalue("dist") == "loadgroup" and ungrouped:
        raise pytest.UsageError(
            f"pytest-xdist's --dist loadgroup did not take with pytest {pytest.__version__} ({ungrouped[0]} has no "
            "group): a group's modules would run in two lanes at once; install the pins of the test extra "
            "(pip install -e '.[test]')")


def pytest_sessionfinish() -> None:
    """Stops the background image run this session started, if it is still going (an interrupted session)."""
    for proc in _IMAGES_AHEAD:
        if proc.poll() is None:
            arm64_project.stop(proc, signal.SIGTERM, 60)  # the script then stops its own step


@pytest.fixture(scope="session")
def arm64_images() -> None:
    """Waits until the background run of :mod:`arm64_project` has made the arm64 suites' images; when it failed,
    says so (the suite's own prepare-base then builds them and fails with the real error if it must)."""
    failed = arm64_project.wait_for_images()
    if failed:
        print(f"the arm64 images were not made ahead of time ({arm64_project.LOG}):\n{failed}")


def start_process(argv: list[str], *, env: Mapping[str, str] | None = None, **popen: Any) -> subprocess.Popen[str]:
    """``argv`` left running in a process group of its own (stdin from /dev/null and text pipes unless
    ``popen`` says otherwise); its process group is killed when the current test ends."""
    options: dict[str, Any] = {"stdin": subprocess.DEVNULL, "stdout": subprocess.PIPE, "stderr": subprocess.PIPE,
                               "text": True, **popen}
    proc: subprocess.Popen[str] = subprocess.Popen(argv, env=env, start_new_session=True, **options)
    _STARTED.append(proc)
    return proc


def stop_process(proc: subprocess.Popen[str]) -> None:
    """Kill ``proc``'s process group (SIGKILL: the process and what it started, such as ssh or rsync, even
    when the process itself already ended), wait for it and close its pipes."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    for stream in (proc.stdin, proc.stdout, proc.stderr):
        if stream is not None:
            stream.close()


@pytest.fixture(autouse=True)
def _stop_started_processes() -> Iterator[None]:
    """Kills what the test left running of the processes it started (not those of wider fixtures)."""
    mark = len(_STARTED)
    yield
    while len(_STARTED) > mark:
        stop_process(_STARTED.pop())


@pytest.fixture
def background() -> Callable[..., subprocess.Popen[str]]:
    """``background(argv, **popen)``: a command other than robocore's CLI left running (:func:`start_process`)."""
    return start_process


class RobocoreCli:
    """robocore's command line as a user runs it: ``python -m robocore [-p PROJECT] ARGS`` in a subprocess.

    Every way takes ``env``: variables set on top of this process's environment, ``None`` removing
    one (e.g. ``{"DISPLAY": None}``). Standard input is /dev/null unless a terminal is asked for, so
    that the CLI never sees the terminal pytest may have been started from.
    """

    def argv(self, project: Path | None, *args: str) -> list[str]:
        """The command line: this interpreter, ``-m robocore``, ``-p PROJECT`` when given, ``args``."""
        return [sys.executable, "-m", "robocore", *(["-p", str(project)] if project is not None else []), *args]

    def environ(self, env: Env | None = None) -> dict[str, str]:
        """This process's environment with ``env`` applied (``None`` values remove the variable)."""
        full = dict(os.environ)
        for name, value in (env or {}).items():
            if value is None:
                full.pop(name, None)
            else:
                full[name] = value
        return full

    def __call__(self, project: Path | None, *args: str, check: bool = True, env: Env | None = None,
                 timeout: float = 1800) -> subprocess.CompletedProcess[str]:
        """Run the CLI to its end and return the completed process (text stdout and stderr). With ``check``,
        a non-zero exit fails the test with the command line, the exit code and the ends of both outputs. (It
        runs in a test phase, which already waits while another lane runs a quiet test: :func:`lanes.working`.)"""
        argv = self.argv(project, *args)
        proc = subprocess.run(argv, env=self.environ(env), stdin=subprocess.DEVNULL, capture_output=True,
                              text=True, timeout=timeout)
        if check and proc.returncode != 0:
            pytest.fail(f"`robocore {shlex.join(argv[3:])}` failed: {output_tails(proc, 4000)}", pytrace=False)
        return proc

    def start(self, project: Path | None, *args: str, env: Env | None = None,
              **popen: Any) -> subprocess.Popen[str]:
        """The CLI left running, for a test that reads it live or acts meanwhile (:func:`start_process`:
        killed with its process group when the test ends)."""
        return start_process(self.argv(project, *args), env=self.environ(env), **popen)

    def in_terminal(self, project: Path | None, *args: str, typed: str, env: Env | None = None,
                    timeout: float = 60) -> subprocess.CompletedProcess[str]:
        """The CLI on a new pseudo-terminal, its controlling terminal as in an interactive session: ``typed``
        is written to the terminal, and all the terminal showed until the CLI exited is the result's stdout
        (stderr is empty: one terminal carries both). Killed after ``timeout`` seconds (exit code -9)."""
        argv = self.argv(project, *args)
        environ = self.environ(env)
        pid, fd = pty.fork()
        if pid == 0:  # the child: the CLI on the terminal
            try:
                os.execve(argv[0], argv, environ)
            finally:
                os._exit(127)
        output = b""
        deadline = time.monotonic() + timeout
        try:
            os.write(fd, typed.encode())
            while time.monotonic() < deadline:
                ready, _, _ = select.select([fd], [], [], 1.0)
                if not ready:
                    continue
                try:
                    chunk = os.read(fd, 4096)
                except OSError:  # the child closed the terminal
                    break
                if not chunk:
                    break
                output += chunk
        finally:
            status = _reap(pid, grace=10 if time.monotonic() < deadline else 0)
            os.close(fd)
        return subprocess.CompletedProcess(argv, os.waitstatus_to_exitcode(status), output.decode(errors="replace"), "")


def _reap(pid: int, grace: float) -> int:
    """Wait up to ``grace`` seconds for child ``pid`` to exit, then kill it; return its wait status."""
    end = time.monotonic() + grace
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return status
        if time.monotonic() >= end:
            os.kill(pid, signal.SIGKILL)
            return os.waitpid(pid, 0)[1]
        time.sleep(0.05)


@pytest.fixture(scope="module")
def official_names() -> Iterator[None]:
    """Held for a whole module by the official-base suites (test_official_base.py, test_official_arm64.py): the
    stand-ins of the official images are named as a pull leaves them (``ros:noetic-ros-base``), and Docker holds one
    arch of a name at a time, so one suite must not name the other arch meanwhile."""
    with lanes.one_at_a_time("official-names"):
        yield


@pytest.fixture(scope="session")
def run_robocore() -> RobocoreCli:
    """``run_robocore(project, *args, check=True, env=None, timeout=1800)``: the robocore CLI (:class:`RobocoreCli`)."""
    return RobocoreCli()


@pytest.fixture(scope="session")
def docker_client() -> Iterator[Any]:
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


@pytest.fixture
def tracked_containers(docker_client: Any) -> Iterator[list[Any]]:
    """A list for the containers a test starts itself: each is removed (forced, with its anonymous volumes)
    when the test ends, pass or fail."""
    from docker.errors import NotFound

    started: list[Any] = []
    yield started
    for container in started:
        with contextlib.suppress(NotFound):
            container.remove(force=True, v=True)


@pytest.fixture(scope="session")
def new_demo_project(docker_client: Any, run_robocore: RobocoreCli) -> Iterator[Callable[[], Path]]:
    """``new_demo_project()``: ``robocore init TMP/robocore-it-demo --defaults --base wheels``, the template
    project on the wheels base in a new temporary folder; every such folder is removed when the session ends."""
    parents: list[Path] = []

    def make() -> Path:
        parents.append(Path(tempfile.mkdtemp(prefix="robocore-it-")))
        root = parents[-1] / DEMO_NAME
        run_robocore(None, "init", str(root), "--defaults", "--base", "wheels")
        return root

    yield make
    for parent in parents:
        shutil.rmtree(parent, ignore_errors=True)


@pytest.fixture(scope="session")
def demo_project(new_demo_project: Callable[[], Path], run_robocore: RobocoreCli) -> Path:
    """The template project (wheels base) after prepare-base, stage and build; returns its folder."""
    root = new_demo_project()
    with lanes.one_at_a_time("demo"):  # the first lane builds the images; the next finds them current
        for step in ("prepare-base", "stage", "build"):
            run_robocore(root, step, "--quiet")
    return root


@pytest.fixture
def project_copies(demo_project: Path, tmp_path: Path, docker_client: Any) -> Iterator[Callable[..., Path]]:
    """``project_copies(kind, transport="shm", edit=None)``: a copy of the built demo project named
    ``robocore-it-<kind>-<n>-<stamp>`` (:func:`deploy_helpers.copy_project`: its own containers, discovery
    port and ROS domain). When the test ends, the containers, discovery server volumes and pytest-plugin
    test runs of every copy are removed."""
    made: list[str] = []

    def make(kind: str, **kwargs: Any) -> Path:
        name = f"robocore-it-{kind}-{lanes.lane()}{len(made)}-{int(time.time() * 1000) % 100000}"
        made.append(name)
        return copy_project(demo_project, tmp_path, name, **kwargs)

    yield make
    for name in made:
        remove_test_runs(docker_client, name)
        remove_project_containers(docker_client, name)


@pytest.fixture
def robot_run(project_copies: Callable[..., Path]) -> Iterator[Callable[..., Any]]:
    """``robot_run(root=None, servers=True, graph=True)``: project ``root`` (default: a ``robocore-it-probe-*``
    copy of the demo project) brought up by robocore's pytest plugin machinery (``robocore.testing.bring_up``);
    every run is closed when the test ends."""
    from robocore.testing import bring_up

    runs: list[Any] = []

    def start(root: Path | None = None, *, servers: bool = True, graph: bool = True) -> Any:
        runs.append(bring_up(root or project_copies("probe"), servers=servers, graph=graph))
        return runs[-1]

    yield start
    for run in runs:
        run.close()


class Restorer:
    """Puts files and folders back as they were when kept: the same content, or absent if they did not exist.

    A file gets its content back (written anew, so that tools comparing times see a change); a folder
    is copied back with its files' times; ``then(action)`` runs after everything is back (e.g. a
    rebuild of a shared project, whose build must match its sources again).
    """

    def __init__(self, backups: Path) -> None:
        self.backups = backups
        self.kept: list[tuple[Path, Path | None]] = []
        self.actions: list[Callable[[], object]] = []

    def keep(self, *paths: Path) -> None:
        """Remember ``paths`` as they are now."""
        for path in paths:
            backup: Path | None = None
            if path.is_dir() and not path.is_symlink():
                backup = self.backups / str(len(self.kept))
                shutil.copytree(path, backup, symlinks=True)
            elif path.exists() or path.is_symlink():
                backup = self.backups / str(len(self.kept))
                shutil.copy2(path, backup, follow_symlinks=False)
            self.kept.append((path, backup))

    def then(self, action: Callable[[], object]) -> None:
        """Run ``action`` once everything kept is back."""
        self.actions.append(action)

    def restore(self) -> None:
        """Put back every kept path (the last kept first), then run the actions."""
        for path, backup in reversed(self.kept):
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path)
            if backup is None:
                path.unlink(missing_ok=True)
            elif backup.is_dir():
                shutil.copytree(backup, path, symlinks=True)
            elif backup.is_symlink():
                path.unlink(missing_ok=True)
                path.symlink_to(os.readlink(backup))
            else:
                path.write_bytes(backup.read_bytes())
        for action in self.actions:
            action()


@pytest.fixture
def restore(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Restorer]:
    """``restore.keep(path, ...)`` before a test edits, moves or creates paths in a shared project: they are
    put back when the test ends, pass or fail (:class:`Restorer`)."""
    restorer = Restorer(tmp_path_factory.mktemp("restore"))
    yield restorer
    restorer.restore()


@pytest.fixture(scope="module")
def robot_fleets(docker_client: Any) -> Iterator[Callable[..., RobotFleet]]:
    """``robot_fleets(count=2, env=None, setup=None)``: a started :class:`RobotFleet` of simulated robot hosts;
    every fleet of the module (hosts, network, keys) is removed after the module's last test."""
    fleets: list[RobotFleet] = []

    def start(count: int = 2, **kwargs: Any) -> RobotFleet:
        fleet = RobotFleet(count, **kwargs)
        fleets.append(fleet)  # before start: a fleet that fails halfway is removed too
        with lanes.one_at_a_time("robot-host"):  # one lane bootstraps the hosts' image, the others find it made
            ensure_image()
        fleet.start()
        return fleet

    yield start
    for fleet in reversed(fleets):  # reversed: each restores the ROBOCORE_SSH_CONFIG it found
        fleet.close()


@pytest.fixture(scope="module")
def fleet(robot_fleets: Callable[..., RobotFleet]) -> RobotFleet:
    """Two simulated robot hosts reached over ssh://. One fleet per module, not per session: suites stop
    hosts and leave releases on them."""
    return robot_fleets(2)
