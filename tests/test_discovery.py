"""The discovery interface: the registry, a second (test-only) kind end to end, readiness, the transport."""

from __future__ import annotations

import os
import subprocess
import time
from pathlib import Path
from typing import Any

import pytest
import yaml
from fakes import FakeContainer, FakeDocker

from robocore.commands import run
from robocore.commands.run import wait_server_ready
from robocore.commands.status import super_client_exec_env
from robocore.commands.support.composefiles import write_dds_profiles
from robocore.commands.support.reporting import Reporter
from robocore.config.loader import parse_robot_text
from robocore.config.model import Robot
from robocore.errors import ConfigError, DockerError
from robocore.files import WRITTEN_RECORD
from robocore.plan import compose, containers, discovery, naming, testrun
from robocore.plan.actions import Action
from robocore.plan.discovery import (
    IN_CONTAINERS,
    Discovery,
    FileLocator,
    Readiness,
    ServerEndpoint,
    ServerProcess,
    ServerState,
    Transport,
    fastdds,
    server_script,
)
from robocore.plan.discovery.base import READY, WAITING, last_error_line
from robocore.project import Project

ROBOT: dict[str, Any] = {
    "ros_distro": "jazzy",
    "ros_domain_id": 3,
    "hosts": [
        {"name": "dev", "ip": "192.168.1.10", "docker": "local"},
        {"name": "pi", "ip": "192.168.1.20", "user": "pi"},
    ],
    "components": [
        {"name": "talker", "runs_on": "dev", "folder": "components/talker", "entrypoint": "ros2 run demo talker"},
        {"name": "cam", "runs_on": "pi", "folder": "components/cam"},
    ],
}


def robot(**discovery_settings: Any) -> Robot:
    return Robot.model_validate({**ROBOT, "discovery": discovery_settings})


def with_kind(source: Robot, kind: str) -> Robot:
    """``source`` with ``discovery.kind`` set to a value robot.yaml's schema does not know (as a new kind would be)."""
    return source.model_copy(update={"discovery": source.discovery.model_copy(update={"kind": kind})})


class Master(Discovery):
    """A test-only kind shaped like a ROS 1 master: one master on the first host, its URI and the node's own
    address in every node's environment, a readiness line, no profile for observers."""

    kind = "master"
    PORT = 11311
    STATE = "/robocore/master"

    def servers(self) -> list[ServerEndpoint]:
        first = self.robot.hosts[0]
        return [ServerEndpoint(index=0, host=first.name, address=first.ip, port=self.PORT)]

    def server_process(self, index: int) -> ServerProcess:
        return ServerProcess(command=("roscore", "-p", str(self.PORT)),
                             environment={"ROS_IP": self.servers()[index].address}, state_dir=self.STATE)

    def _uri(self) -> str:
        return f"http://{self.servers()[0].locator}"

    def client_environment(self, host: str, files: FileLocator = IN_CONTAINERS, *,
                           network_mode: str = "host") -> dict[str, str]:
        env = {"ROS_MASTER_URI": self._uri(), "ROS_IP": self.robot.host(host).ip}
        path = files("master.txt")
        if path is not None:
            env["MASTER_FILE"] = path
        return env

    def observer_environment(self, host: str | None = None, files: FileLocator = IN_CONTAINERS) -> dict[str, str]:
        env = {"ROS_MASTER_URI": self._uri()}
        if host is not None:
            env["ROS_IP"] = self.robot.host(host).ip
        return env

    def files(self) -> dict[str, str]:
        return {"master.txt": self._uri() + "\n"}

    def readiness(self, log_text: str, state: ServerState) -> Readiness:
        if "started core service" in log_text:
            return READY
        if state.status != "running" or state.timed_out:
            return Readiness("failed", last_error_line(log_text), hint="is another master on that port?")
        return WAITING

    def node_list_argv(self, spin_seconds: float) -> list[str]:
        return [naming.ENTRYPOINT, "rosnode", "list"]


@pytest.fixture
def master(monkeypatch: pytest.MonkeyPatch) -> None:
    """Register the test-only ``master`` kind for one test."""
    monkeypatch.setitem(discovery.KINDS, Master.kind, Master)


# ------------------------------------------------------------------ the registry


def test_the_default_kind_is_fast_dds() -> None:
    kind = discovery.for_robot(robot())
    assert isinstance(kind, fastdds.FastDds) and kind.kind == "fastdds" == robot().discovery_kind
    assert robot().discovery.kind is None  # robot.yaml says nothing: the distro's kind


def test_the_registry_refuses_an_unknown_kind_naming_the_setting() -> None:
    with pytest.raises(ConfigError) as error:
        discovery.for_robot(with_kind(robot(), "zenoh"))
    assert error.value.lines() == [
        "robot.yaml: discovery.kind: unknown discovery kind 'zenoh' (known: fastdds, rosmaster)"]


def test_an_unregistered_kind_fails_the_container_plan_too() -> None:
    """Negative control of the end-to-end test below: without the registration, no plan."""
    project = Project(root=Path("/srv/myrobot"), robot=with_kind(robot(), "master"))
    with pytest.raises(ConfigError, match=r"discovery\.kind: unknown discovery kind 'master'"):
        containers.host_specs(project, "dev")


def test_robot_yaml_accepts_only_kinds_it_documents() -> None:
    text = yaml.safe_dump({**ROBOT, "discovery": {"kind": "fastdds"}})
    assert parse_robot_text(text).discovery.kind == "fastdds"
    with pytest.raises(ConfigError) as error:
        parse_robot_text(yaml.safe_dump({**ROBOT, "discovery": {"kind": "roscore"}}, sort_keys=False))
    assert any("discovery.kind: 'roscore' is not one of: fastdds" in line for line in error.value.lines())


# ------------------------------------------------------------------ a second kind, end to end


def test_a_registered_kind_shapes_every_container(master: None) -> None:
    project = Project(root=Path("/srv/myrobot"), robot=with_kind(robot(), "master"))
    dev = {s.service: s for s in containers.host_specs(project, "dev")}
    assert list(dev) == ["discovery-0", "talker"]
    server = dev["discovery-0"]
    assert server.command == ("roscore", "-p", "11311")
    assert server.entrypoint == (naming.ENTRYPOINT,) and server.image == "myrobot-base:latest"
    assert server.env == {"ROS_IP": "192.168.1.10"}
    assert [(m.source, m.target) for m in server.mounts] == [("myrobot-discovery-0-state", Master.STATE)]
    assert server.ipc_mode == "host"  # the transport (shm by default), not the kind, decides
    talker = dev["talker"]
    assert talker.env["ROS_MASTER_URI"] == "http://192.168.1.10:11311"
    assert talker.env["ROS_IP"] == "192.168.1.10"
    assert talker.env["MASTER_FILE"] == "/robocore/dds/master.txt"
    assert "ROS_DISCOVERY_SERVER" not in talker.env and "RMW_IMPLEMENTATION" not in talker.env
    assert talker.depends_on == ("discovery-0",)
    (cam,) = containers.host_specs(project, "pi")
    assert cam.env["ROS_IP"] == "192.168.1.20"  # each node gets its own host's address
    assert cam.depends_on == ()
    assert containers.state_volumes(project, "dev") == ["myrobot-discovery-0-state"]
    assert containers.state_volumes(project, "pi") == []
    document = yaml.safe_load(compose.render(project, "dev"))
    assert document["services"]["discovery-0"]["command"] == ["roscore", "-p", "11311"]
    assert document["volumes"] == {"myrobot-discovery-0-state": {"name": "myrobot-discovery-0-state"}}


def test_a_registered_kind_writes_its_files_and_drops_the_previous_kinds(master: None, tmp_path: Path) -> None:
    before = Project(root=tmp_path, robot=robot())
    write_dds_profiles(before)
    folder = tmp_path / ".robocore" / "dds"
    assert sorted(p.name for p in folder.iterdir()) == [WRITTEN_RECORD, "client-1.xml", "client-2.xml",
                                                         "client-3.xml", "client.xml", "super_client.xml"]
    (folder / ".client.xml.123.tmp").write_text("another writer's temp file")
    after = Project(root=tmp_path, robot=with_kind(robot(), "master"))
    written = write_dds_profiles(after)
    assert written == [folder / "master.txt"]
    assert (folder / "master.txt").read_text() == "http://192.168.1.10:11311\n"
    assert sorted(p.name for p in folder.iterdir()) == [".client.xml.123.tmp", WRITTEN_RECORD, "master.txt"]


def test_a_registered_kind_reaches_status_and_the_test_run(master: None) -> None:
    source = with_kind(robot(), "master")
    project = Project(root=Path("/srv/myrobot"), robot=source)
    assert super_client_exec_env(project, "pi") == {"ROS_MASTER_URI": "http://192.168.1.10:11311",
                                                    "ROS_IP": "192.168.1.20"}
    run = testrun.TestRun(project="myrobot", run_id="0123abcd", domain_id=42, owner="x")
    isolated = Project(root=project.root, robot=testrun.isolated_robot(source, {"dev": "172.30.0.2"}, 42))
    (server,) = testrun.server_specs(run, isolated, "/tmp/run/dds")
    assert server.command == ("roscore", "-p", "11311")
    assert [(m.source, m.target) for m in server.mounts] == [("myrobot-t0123abcd-discovery-0-state", Master.STATE)]
    assert testrun.probe_profile(isolated.robot) == ""  # its observers read no file
    assert testrun.probe_environment(isolated.robot, "/tmp/run/probe.xml") == {
        "ROS_MASTER_URI": "http://172.30.0.2:11311"}


# ------------------------------------------------------------------ readiness

#: What Fast DDS's ``fastdds discovery`` prints, with its colour codes.
STARTED = ("\x1b[1;34m### Server is running ###\x1b[0m\n"
           "  Participant Type:   SERVER\n  Security:           NO\n  Server ID:          0\n")
RESTART_HOLD = ("robocore: discovery server restarted; silent for 12 s so that clients drop the previous instance\n")
PORT_IN_USE = (
    "\x1b[31;1m2025-01-07 10:00:00.100 [RTPS_TRANSPORT_SHM Error] Failed to create segment: "
    "Address already in use -> Function compute_per_allocation_extra_size\x1b[0m\n"
    "2025-01-07 10:00:00.200 [RTPS_NETWORK Error] UDPTransport Error binding at port: (11811) with msg: bind: "
    "Address already in use -> Function CreateInputChannelResource\n"
    "Shutting down the server\n"
)
RUNNING = ServerState(status="running")


@pytest.mark.parametrize("distro_log", [STARTED, RESTART_HOLD, "Server started at 10.0.0.1:11811\n"])
def test_fast_dds_server_is_ready_once_it_says_so_or_holds_after_a_restart(distro_log: str) -> None:
    assert fastdds.readiness(distro_log, RUNNING) == READY
    assert fastdds.readiness(distro_log, RUNNING).ready


def test_fast_dds_server_without_its_line_is_waiting() -> None:
    assert fastdds.readiness("", RUNNING) == WAITING
    assert fastdds.readiness("Starting...\n", ServerState("created")) == WAITING


def test_port_in_use_fails_with_the_last_error_line() -> None:
    verdict = fastdds.readiness(PORT_IN_USE, ServerState(status="restarting", restart_count=1))
    assert verdict.failed
    assert verdict.reason == ("2025-01-07 10:00:00.200 [RTPS_NETWORK Error] UDPTransport Error binding at port: "
                              "(11811) with msg: bind: Address already in use -> Function CreateInputChannelResource")
    assert verdict.hint is not None and "discovery.servers[].port" in verdict.hint


def test_a_restarted_server_fails_even_though_its_first_start_logged_ready() -> None:
    """The first start's ready line stays in the log: the restart count says it failed since."""
    assert fastdds.readiness(STARTED + PORT_IN_USE, ServerState("running", restart_count=1)).failed
    assert fastdds.readiness(STARTED, ServerState("running", restart_count=0)).ready  # control


def test_an_exited_or_late_server_fails_with_its_last_line() -> None:
    exited = fastdds.readiness("usage: fastdds discovery ...\n", ServerState("exited"))
    assert exited.failed and exited.reason == "usage: fastdds discovery ..."
    late = fastdds.readiness("", ServerState("running", timed_out=True))
    assert late.failed and late.reason == "no output"


def test_a_long_error_line_is_cut_to_its_end() -> None:
    line = "[RTPS Error] " + "x" * 300 + " END"
    assert fastdds.readiness(line, ServerState("exited")).reason == line[-200:]


def test_the_wait_loop_polls_until_the_kind_says_ready() -> None:
    spec = containers.discovery_spec(Project(root=Path("/srv/r"), robot=robot()), 0)
    container = FakeContainer(["starting\n", "", STARTED])
    wait_server_ready(container, spec, robot().hosts[0], fastdds.readiness, timeout=60)
    assert container.polls == 3


def test_the_wait_loop_reports_the_kinds_failure_with_its_hint() -> None:
    spec = containers.discovery_spec(Project(root=Path("/srv/r"), robot=robot()), 0)
    with pytest.raises(DockerError) as error:
        wait_server_ready(FakeContainer([PORT_IN_USE], status="restarting", restarts=1), spec, robot().hosts[0],
                          fastdds.readiness)
    message, hint = error.value.lines()
    assert message.startswith("host dev: discovery server discovery-0 did not start (restarting): ")
    assert message.endswith("Address already in use -> Function CreateInputChannelResource")
    assert hint == f"hint: {fastdds.PORT_HINT}"


# ------------------------------------------------------------------ the transport


@pytest.mark.parametrize(("setting", "network", "ipc"), [
    ("shm", "host", "host"), ("shm", "bridge", None), ("udp", "host", None), ("udp", "bridge", None)])
def test_the_transport_decides_the_ipc_namespace(setting: str, network: str, ipc: str | None) -> None:
    assert Transport.of(robot(transport=setting)).ipc_mode(network) == ipc


def test_fast_dds_renders_the_transport_it_is_given_not_the_robots() -> None:
    shm_robot = robot(transport="shm")
    udp = discovery.for_robot(shm_robot, discovery.UDP)
    assert udp.client_environment("dev")["FASTDDS_BUILTIN_TRANSPORTS"] == "UDPv4"
    assert "<type>UDPv4</type>" in udp.files()["client.xml"] and "<type>SHM</type>" not in udp.files()["client.xml"]
    own = discovery.for_robot(shm_robot)
    assert "FASTDDS_BUILTIN_TRANSPORTS" not in own.client_environment("dev")  # control: the robot's shm
    assert "<type>SHM</type>" in own.files()["client.xml"]


# ------------------------------------------------------------------ Fast DDS behind the interface


def test_fast_dds_interface_matches_its_module_functions() -> None:
    r = robot(servers=[{"host": "pi", "port": 12000}, {"host": "dev"}])
    kind = discovery.for_robot(r)
    assert kind.client_environment("pi") == fastdds.client_environment(r)
    assert kind.observer_environment() == fastdds.client_environment(r, super_client=True)
    assert kind.files() == fastdds.profile_files(r)
    assert [(s.index, s.host, s.locator) for s in kind.servers_on("dev")] == [(1, "dev", "192.168.1.10:11811")]
    process = kind.server_process(0)
    assert process.command[4:] == (*fastdds.server_command(r, 0), "-x", fastdds.DISCOVERY_PROFILE)
    assert process.state_dir == fastdds.DISCOVERY_STATE


def test_an_observer_without_the_files_gets_no_profile_variable() -> None:
    kind = discovery.for_robot(robot())
    env = kind.observer_environment("dev", files=discovery.no_files)
    assert env["ROS_SUPER_CLIENT"] == "TRUE"
    assert not any(key.endswith("_DEFAULT_PROFILES_FILE") for key in env)
    assert kind.observer_environment("dev")["FASTDDS_DEFAULT_PROFILES_FILE"] == "/robocore/dds/super_client.xml"


def test_node_listing_keeps_named_nodes_and_drops_hidden_ones() -> None:
    kind = discovery.for_robot(robot())
    assert kind.node_list_argv(3.0)[1:] == ["ros2", "node", "list", "--no-daemon", "--spin-time", "3.0"]
    output = "/talker\n/ns/listener\n/_ros2cli_1234\nWARNING: something\n/talker\n"
    assert kind.nodes_from_output(output) == ["/ns/listener", "/talker"]


# ------------------------------------------------------------------ replacing a node


@pytest.mark.parametrize(("old_profile", "new_profile"),
                         [("client.xml", "client-1.xml"), ("client-1.xml", "client-2.xml"),
                          ("client-3.xml", "client.xml")])
def test_a_replaced_node_gets_the_next_profile_after_its_predecessors_and_the_same_spec_hash(
        old_profile: str, new_profile: str) -> None:
    project = Project(root=Path("/srv/r"), robot=robot())
    kind = discovery.for_robot(project.robot)
    specs = containers.host_specs(project, project.robot.hosts[0].name)
    spec = next(s for s in specs if s.role != naming.ROLE_DISCOVERY)
    old_env = {**spec.env, **{n: f"/robocore/dds/{old_profile}" for n in fastdds.PROFILE_VARIABLES}}
    old = FakeContainer(attrs={"Config": {"Env": [f"{k}={v}" for k, v in old_env.items()]}})
    client = FakeDocker()
    run.apply_action(client, Action("replace", spec.name, "new image"), spec, old,  # type: ignore[arg-type]
               project.robot.hosts[0], report=Reporter(quiet=True), kind=kind, ready_timeout=run.SERVER_READY_TIMEOUT)
    [made] = client.containers.created
    assert old.removed and made["environment"]["FASTDDS_DEFAULT_PROFILES_FILE"] == f"/robocore/dds/{new_profile}"
    assert made["labels"] == spec.labels  # a later run compares the spec's hash: it keeps this container


# ------------------------------------------------------------------ the server script's restart hold

def run_server_script(state: Path, server: str, *, hold: int = 12, init: bool = True,
                      alive_age: float | None = None, started: bool = False) -> tuple[int, str, list[str]]:
    """Run :data:`server_script.DISCOVERY_SCRIPT` on this machine's sh, its state volume a folder of ``state``, a
    ``sh -c server`` standing in for the server and a ``sleep`` that only writes down how long it was asked to
    wait (the heartbeat's sleeps included). Returns the exit code, the output and the hold's sleeps."""
    bin_dir, volume = state / "bin", state / "volume"
    bin_dir.mkdir(exist_ok=True)
    volume.mkdir(exist_ok=True)
    (bin_dir / "sleep").write_text(f'#!/bin/sh\necho "$1" >> {state}/slept\n')
    (bin_dir / "sleep").chmod(0o755)
    if started:
        (volume / "started").touch()
    if alive_age is not None:
        (volume / "alive").touch()
        stamp = time.time() - alive_age
        os.utime(volume / "alive", (stamp, stamp))
    script = (server_script.DISCOVERY_SCRIPT.replace(server_script.DISCOVERY_STATE, str(volume))
              .replace(server_script.DISCOVERY_PROFILE, str(state / "profile.xml")))
    env = {"PATH": f"{bin_dir}:{os.environ['PATH']}", "ROBOCORE_DS_HOLD": str(hold), "ROBOCORE_DS_XML": "<dds/>"}
    if init:
        env[naming.INIT_SIGNALS_GROUP] = "1"
    done = subprocess.run(["sh", "-c", script, "robocore-discovery", "sh", "-c", server], env=env,
                          capture_output=True, text=True, timeout=30, check=False)
    slept = (state / "slept").read_text().split() if (state / "slept").exists() else []
    return done.returncode, done.stdout, [s for s in slept if s != str(server_script.HEARTBEAT_SECONDS)]


def markers(state: Path) -> list[str]:
    return sorted(p.name for p in (state / "volume").iterdir())


def test_a_first_start_serves_at_once_and_a_clean_stop_leaves_no_hold_behind(tmp_path: Path) -> None:
    code, out, slept = run_server_script(tmp_path, "exit 0")
    assert (code, slept, "restarted" in out) == (0, [], False)
    assert markers(tmp_path) == []
    assert (tmp_path / "profile.xml").read_text() == "<dds/>\n"


def test_a_server_that_ended_badly_leaves_its_markers_and_its_exit_code(tmp_path: Path) -> None:
    code, _, slept = run_server_script(tmp_path, "sleep 1; exit 3")
    assert (code, slept) == (3, [])
    assert markers(tmp_path) == ["alive", "started"]


def test_the_heartbeat_keeps_alive_fresh_while_the_server_runs(tmp_path: Path) -> None:
    """The server makes ``alive`` an hour old; while it runs on (0.5 s), the beat writes it again."""
    alive = tmp_path / "volume" / "alive"
    server = f'touch -d "1 hour ago" {alive}; python3 -c "import time; time.sleep(0.5)"; exit 3'
    code, _, _ = run_server_script(tmp_path, server)
    assert code == 3 and time.time() - alive.stat().st_mtime < 30


@pytest.mark.parametrize(("alive_age", "silent"), [(5, {7, 8}), (0.2, {12}), (-3600, {12}), (14, {0}), (3600, {0})])
def test_a_restarted_server_holds_only_what_is_left_since_its_last_heartbeat(
        tmp_path: Path, alive_age: float, silent: set[int]) -> None:
    """Hold + one heartbeat period after the last heartbeat, at most the whole hold (a clock behind the
    heartbeat holds in full). The script counts whole seconds: the age is one of two."""
    code, out, slept = run_server_script(tmp_path, "exit 0", alive_age=alive_age, started=True)
    assert code == 0
    held = [int(s) for s in slept] or [0]
    assert len(held) == 1 and held[0] in silent, out
    assert ("silent for" in out) == (held[0] > 0)


def test_a_server_without_heartbeats_holds_in_full_and_none_is_held_without_a_hold(tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    assert run_server_script(tmp_path / "a", "exit 0", started=True)[2] == ["12"]  # ran before heartbeats
    assert run_server_script(tmp_path / "b", "exit 0", started=True, hold=0, alive_age=1)[2] == []


def test_without_docker_init_the_server_is_execd_and_its_next_start_holds_in_full(tmp_path: Path) -> None:
    """No init passes SIGTERM on (a Kubernetes pod): the server replaces the script, so nothing is left to see
    its clean stop or keep heartbeats; the next start holds the whole time."""
    parent = 'echo "parent $PPID"; exit 0'
    code, out, _ = run_server_script(tmp_path, parent, init=False, alive_age=600)
    assert code == 0 and f"parent {os.getpid()}" in out  # this test's process: the script was replaced
    assert markers(tmp_path) == ["started"]
    code, out, slept = run_server_script(tmp_path, parent)
    assert slept == ["12"] and f"parent {os.getpid()}" not in out  # with init, the script stays the parent
