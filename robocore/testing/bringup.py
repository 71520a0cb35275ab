"""Bring a robot project up on the local Docker daemon for tests, isolated, and take it down again.

:class:`RobotUnderTest` is what the ``robot`` fixture hands to a test: it builds what changed
(``prepare-base``, ``stage``, ``build`` with their content-hash caches, one project's builds at a
time), starts the run's host containers, discovery servers and components through
testcontainers (see :mod:`robocore.plan.testrun` for the isolation), and joins the graph with
:class:`~robocore.testing.graph.Graph`. What a SIGKILLed run leaves behind is removed by the
next run on the same machine; nothing relies on testcontainers' Ryuk (its image comes from a
registry).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import secrets
import socket
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from robocore.errors import RobocoreError
from robocore.files import SHARED, make_folder, remove_tree, write_atomic
from robocore.plan import discovery, naming, testrun
from robocore.plan.containers import ContainerSpec
from robocore.plan.testrun import TestRun
from robocore.project import Project
from robocore.testing import ros_env
from robocore.testing.domains import reserve_domain
from robocore.testing.errors import BringUpError
from robocore.testing.faults import Faults
from robocore.testing.graph import Graph

os.environ.setdefault("TESTCONTAINERS_RYUK_DISABLED", "true")

#: Seconds a component may take to stop before it is killed (restart, stop, end of run).
STOP_TIMEOUT = 5
#: Seconds after the last start during which a component that exits fails the bring-up.
START_GRACE = 1.0
#: Log lines of each container shown when a component dies at start or a test fails.
LOG_TAIL = 20


#: What ``robot.graph`` says on a ROS 1 robot: the test process's node is an rclpy (ROS 2) node.
ROS1_GRAPH = ("robot.graph joins ROS 2 graphs only, and {distro} is ROS 1: use robot.wait_for_log, robot.logs "
              "or robot.exec (e.g. ['rostopic', 'echo', '-n', '1', '/chatter'])")


def _boot_id() -> str:
    try:
        return Path("/proc/sys/kernel/random/boot_id").read_text().strip()
    except OSError:
        return "unknown"


def _start_ticks(pid: int) -> str | None:
    """The start time of process ``pid`` (clock ticks since boot), or None when it does not exist."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat.rsplit(")", 1)[1].split()[19]


def owner() -> str:
    """This process as the owner of a run: host name, boot, pid and start time (pids are reused)."""
    pid = os.getpid()
    return f"{socket.gethostname()}|{_boot_id()}|{pid}|{_start_ticks(pid)}"


def owner_is_gone(text: str) -> bool:
    """True when ``text`` names a process of this machine, this boot, that no longer runs."""
    parts = text.split("|")
    if len(parts) != 4 or parts[0] != socket.gethostname() or parts[1] != _boot_id():
        return False  # another machine's run (a shared daemon): not ours to judge
    try:
        pid = int(parts[2])
    except ValueError:
        return False
    return _start_ticks(pid) != parts[3]


def reap_leftovers(client: Any) -> int:
    """Remove the containers, networks and volumes of runs whose process died; return how many containers."""
    from docker.errors import APIError, NotFound

    gone: dict[str, bool] = {}

    def dead(labels: dict[str, str]) -> bool:
        text = labels.get(testrun.LABEL_OWNER, "")
        if text not in gone:
            gone[text] = owner_is_gone(text)
        return gone[text]

    found = client.containers.list(all=True, filters={"label": testrun.LABEL_OWNER}, ignore_removed=True)
    removed = 0
    for container in sorted(found, key=lambda c: c.labels.get(naming.LABEL_ROLE) == testrun.ROLE_HOST):
        if dead(container.labels):
            with contextlib.suppress(NotFound, APIError):
                container.remove(force=True, v=True)
                removed += 1
    for network in client.networks.list(filters={"label": testrun.LABEL_OWNER}):
        if dead(network.attrs.get("Labels") or {}):
            with contextlib.suppress(NotFound, APIError):
                network.remove()
    for volume in client.volumes.list(filters={"label": testrun.LABEL_OWNER}):
        if dead(volume.attrs.get("Labels") or {}):
            with contextlib.suppress(NotFound, APIError):
                volume.remove(force=True)
    return removed


@contextlib.contextmanager
def build_lock(project: Project) -> Iterator[None]:
    """Hold the project's build lock: runs of one project build one at a time (the others find the caches warm)."""
    make_folder(project.state_dir)  # 0700 whatever the umask; a link there is refused
    with open(os.open(project.build_lock, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o600), "a+") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def build_images(project_dir: Path) -> None:
    """prepare-base, stage and build, quietly; each does nothing when its inputs did not change."""
    from robocore.commands import build, prepare_base, stage
    from robocore.commands.support.context import Options

    options = Options(project_dir=project_dir, quiet=True)
    prepare_base.prepare_base(options, force=False)
    stage.stage(options, refresh=False, component=None, force=False)
    build.build(options, component=None, full=False)


def _log_tail(container: Any, lines: int = LOG_TAIL) -> str:
    with contextlib.suppress(Exception):
        return str(container.logs(tail=lines).decode(errors="replace")).rstrip()
    return "(no logs)"


@dataclass
class RobotUnderTest:
    """A robot project running for tests; the ``robot`` fixture."""

    project: Project  # the isolated project: hosts at their run addresses, the run's domain
    run: TestRun
    client: Any  # docker-py client of the local daemon
    run_dir: Path
    containers: dict[str, Any] = field(default_factory=dict)  # service -> testcontainers DockerContainer
    specs: dict[str, ContainerSpec] = field(default_factory=dict)  # service -> its spec
    graph_node: Graph | None = None
    timings: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    _network: Any = None
    _hosts: list[Any] = field(default_factory=list)
    _domain_holder: socket.socket | None = None
    _faults: Faults | None = None
    _closed: bool = False

    # ------------------------------------------------------------------ public API

    @property
    def graph(self) -> Graph:
        """The test process's node in the robot's graph (ROS 2 robots)."""
        if self.graph_node is None and self.project.robot.ros_version == 1:
            raise BringUpError(ROS1_GRAPH.format(distro=self.project.robot.ros_distro.value))
        if self.graph_node is None:
            raise BringUpError("this run has no graph node (brought up without one)")
        return self.graph_node

    @property
    def faults(self) -> Faults:
        """Cut hosts off, partition them, limit a link, power-cut a host (:mod:`robocore.testing.faults`)."""
        if self._faults is None:
            self._faults = Faults(self.client, self.run, self.project, lambda: self.specs, self._container)
        return self._faults

    @property
    def components(self) -> list[str]:
        """Names of the robot's components, in robot.yaml order."""
        return [c.name for c in self.project.robot.components]

    def _container(self, name: str) -> Any:
        try:
            return self.containers[name].get_wrapped_container()
        except KeyError:
            known = ", ".join(self.containers) or "none"
            raise KeyError(f"no component {name!r} in this run (known: {known})") from None

    def logs(self, component: str) -> str:
        """Everything ``component`` printed so far (stdout and stderr)."""
        return str(self._container(component).logs().decode(errors="replace"))

    def wait_for_log(self, component: str, text: str, timeout: float = 10.0) -> str:
        """The first log line of ``component`` containing ``text``; fails the test after ``timeout`` seconds."""
        import pytest

        deadline = time.monotonic() + timeout
        while True:
            for line in self.logs(component).splitlines():
                if text in line:
                    return line
            if time.monotonic() > deadline:
                pytest.fail(f"{component} logged no line containing {text!r} within {timeout} s; last lines:\n"
                            f"{_log_tail(self._container(component))}")
            if self.graph_node is not None:
                self.graph_node.spin(0.1)
            else:
                time.sleep(0.1)

    def restart(self, component: str) -> None:
        """Restart ``component``'s container (SIGTERM, then SIGKILL after a few seconds)."""
        self._container(component).restart(timeout=STOP_TIMEOUT)

    def stop(self, component: str) -> None:
        """Stop ``component``; it is started again before the next test."""
        self._container(component).stop(timeout=STOP_TIMEOUT)

    def kill(self, component: str) -> None:
        """SIGKILL ``component`` (no clean shutdown); :meth:`start` (or the next test) starts it again."""
        self.faults.kill(component)

    def start(self, component: str) -> None:
        """Start ``component`` again after :meth:`stop`."""
        container = self._container(component)
        container.reload()
        if container.status != "running":
            container.start()

    def exec(self, component: str, argv: Sequence[str]) -> tuple[int, str]:
        """Run ``argv`` in ``component``'s container, ROS sourced: (exit code, stdout and stderr)."""
        spec = self.specs.get(component)
        prefix = list(spec.entrypoint) if spec is not None and spec.entrypoint else []
        code, output = self._container(component).exec_run([*prefix, *argv])
        return int(code), str(output.decode(errors="replace"))

    # ------------------------------------------------------------------ lifecycle

    def ensure_running(self) -> list[str]:
        """Undo the faults in force, then start every container a test stopped (servers first); return the
        services started."""
        self.undo_faults()
        started = []
        for service in self.containers:
            container = self._container(service)
            container.reload()
            if container.status != "running":
                container.start()
                started.append(service)
        return started

    def undo_faults(self) -> list[str]:
        """Undo every fault in force; return what was in force (nothing to do when no fault was ever applied)."""
        return self._faults.clear() if self._faults is not None else []

    def faults_in_force(self) -> list[str]:
        """One line per fault in force, for a failed test's report."""
        return self._faults.describe() if self._faults is not None else []

    def report(self) -> str:
        """The last log lines of every container and the graph, for a failed test's report."""
        parts = []
        for service in self.containers:
            parts.append(f"--- {service} (last {LOG_TAIL} lines)\n{_log_tail(self._container(service))}")
        if self.graph_node is not None:
            with contextlib.suppress(Exception):
                parts.append("--- graph\n" + self.graph_node.describe())
        return "\n".join(parts)

    def close(self) -> None:
        """Remove everything the run created. Safe to call twice."""
        if self._closed:
            return
        self._closed = True
        if self.graph_node is not None:
            with contextlib.suppress(Exception):
                self.graph_node.close()
        if self._faults is not None:
            self._faults.close()
        for wrapper in [*reversed(self.containers.values()), *self._hosts]:
            with contextlib.suppress(Exception):
                wrapper.get_wrapped_container().remove(force=True, v=True)
        if self._network is not None:
            with contextlib.suppress(Exception):
                self._network.remove()
        for volume in self.client.volumes.list(filters={"label": f"{testrun.LABEL_RUN}={self.run.run_id}"}):
            with contextlib.suppress(Exception):
                volume.remove(force=True)
        with contextlib.suppress(RobocoreError):
            remove_tree(self.run_dir, ignore_errors=True)
        if self._domain_holder is not None:
            self._domain_holder.close()
        with contextlib.suppress(Exception):
            self.client.close()


def _testcontainer(spec: ContainerSpec, *, network: str | None = None) -> Any:
    """A testcontainers DockerContainer made from ``spec`` (joining ``network`` when given)."""
    from testcontainers.core.container import DockerContainer

    kwargs = spec.docker_kwargs()
    for key in ("image", "name", "environment", "command", "detach"):
        kwargs.pop(key, None)
    if network is not None:
        kwargs.pop("network_mode", None)
    kwargs["network"] = network  # set even when None, so that testcontainers does not pick a network itself
    container = DockerContainer(spec.image, name=spec.name, env=spec.env).with_kwargs(**kwargs)
    if spec.command is not None:
        container.with_command(list(spec.command))
    return container


def _address(wrapper: Any, network: str) -> str:
    container = wrapper.get_wrapped_container()
    container.reload()
    return str(container.attrs["NetworkSettings"]["Networks"][network]["IPAddress"])


def bring_up(project_dir: Path, *, build: bool = True, servers: bool = True, graph: bool = True) -> RobotUnderTest:
    """Build what changed, then start the project isolated on the local daemon; BringUpError on failure.

    ``servers=False`` starts no discovery server, and ``graph=False`` no test-process node: the
    negative controls of robocore's own suites use them. Nothing is left running on failure.
    """
    from robocore.adapters.docker_hosts import local_client

    started = time.monotonic()
    source = Project.load(project_dir)
    graph = graph and source.robot.ros_version == 2  # the test process joins with rclpy: ROS 2 only
    if graph:
        ros_env.check_distro(source.robot.ros_distro.value)
    client = local_client(timeout=300)
    reaped = reap_leftovers(client)
    if build:
        with build_lock(source):
            build_images(source.root)
    built = time.monotonic()
    domain, holder = reserve_domain(client)
    run = TestRun(project=source.name, run_id=secrets.token_hex(4), domain_id=domain, owner=owner())
    run_dir = source.test_runs_dir / run.run_id
    robot = RobotUnderTest(project=source, run=run, client=client, run_dir=run_dir, _domain_holder=holder)
    if reaped:
        robot.notes.append(f"removed {reaped} container(s) left by an earlier run that was killed")
    try:
        _start(robot, source, servers=servers)
        if graph:
            robot.graph_node = _join(robot)
        _check_alive(robot, time.monotonic() + START_GRACE)
    except BaseException:
        robot.close()
        raise
    robot.timings.update(build=built - started, start=time.monotonic() - built, total=time.monotonic() - started)
    return robot


def _start(robot: RobotUnderTest, source: Project, *, servers: bool) -> None:
    from testcontainers.core.network import Network

    from robocore.commands.run import SERVER_READY_TIMEOUT, wait_server_ready
    from robocore.commands.support.arch_checks import allowing_emulation

    run = robot.run
    network = Network(docker_network_kw={"labels": run.labels, "driver": "bridge"})
    network.name = run.network
    robot._network = network.create()
    addresses = {}
    for host in testrun.hosts_to_start(source.robot):
        wrapper = _testcontainer(testrun.host_spec(run, source, host), network=run.network)
        robot._hosts.append(wrapper)
        wrapper.start()
        addresses[host] = _address(wrapper, run.network)
    robot.project = Project(root=source.root, robot=testrun.isolated_robot(source.robot, addresses, run.domain_id))
    dds_dir = robot.run_dir / "dds"
    make_folder(dds_dir, shared=True)  # mounted into the run's containers, whose user may be another
    kind = discovery.for_robot(robot.project.robot)
    for name, text in kind.files().items():
        write_atomic(dds_dir / name, text, mode=SHARED)
    write_atomic(robot.run_dir / "probe.xml", testrun.probe_profile(robot.project.robot), mode=SHARED)
    if servers:
        for spec in testrun.server_specs(run, robot.project, str(dds_dir)):
            for volume in (m.source for m in spec.mounts if m.is_named_volume):
                robot.client.volumes.create(volume, labels=run.labels)
            wrapper = _testcontainer(spec)
            robot.containers[spec.service] = wrapper
            robot.specs[spec.service] = spec
            wrapper.start()
            on = robot.project.robot.host(spec.host)  # this machine's daemon runs every host's containers
            timeout = allowing_emulation(SERVER_READY_TIMEOUT, emulated=on.arch.value != robot.project.native_arch)
            wait_server_ready(wrapper.get_wrapped_container(), spec, on, kind.readiness, timeout)
    for name, spec in testrun.component_specs(run, robot.project, str(dds_dir)).items():
        wrapper = _testcontainer(spec)
        robot.containers[name] = wrapper
        robot.specs[name] = spec
        wrapper.start()


def _join(robot: RobotUnderTest) -> Graph:
    """The test process's node, a super client of the run's servers (UDP), with the project's Python packages."""
    env = testrun.probe_environment(robot.project.robot, str(robot.run_dir / "probe.xml"))
    ros_env.prepare(env)
    for component in robot.project.robot.components:
        if component.has_workspace:
            robot.notes += ros_env.add_install_tree(robot.project.build_dir(component.name) / "install")
    return Graph(f"robocore_test_{robot.run.run_id}", robot.run.domain_id)


def _check_alive(robot: RobotUnderTest, until: float) -> None:
    """BringUpError naming the first container that stopped, with its last log lines."""
    while True:
        for service, wrapper in robot.containers.items():
            container = wrapper.get_wrapped_container()
            container.reload()
            if container.status != "running":
                code = container.attrs.get("State", {}).get("ExitCode")
                raise BringUpError(f"component {service} exited at start (exit code {code}); its last lines:\n"
                                   f"{_log_tail(container)}")
        if time.monotonic() >= until:
            return
        if robot.graph_node is not None:
            robot.graph_node.spin(min(0.2, max(0.0, until - time.monotonic())))
        else:
            time.sleep(0.2)
