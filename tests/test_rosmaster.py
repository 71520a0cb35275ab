"""The ROS master (discovery.kind rosmaster): servers, environments, readiness, node listing, container specs,
and the entrypoint's bridge-address block."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path
from typing import Any

import pytest
import yaml

from robocore import resources
from robocore.config.model import Robot
from robocore.plan import compose, containers, discovery, naming
from robocore.plan.discovery import ServerState, rosmaster
from robocore.plan.discovery.base import READY, WAITING
from robocore.project import Project

ROBOT: dict[str, Any] = {
    "ros_distro": "noetic",
    "hosts": [
        {"name": "dev", "ip": "192.168.1.10", "docker": "local"},
        {"name": "pi", "ip": "192.168.1.20", "user": "pi"},
        {"name": "nuc", "ip": "nuc.local", "user": "robot"},
        {"name": "arm", "ip": "fd00::20", "user": "robot"},
    ],
    "components": [
        {"name": "talker", "runs_on": "dev", "folder": "components/talker", "entrypoint": "rosrun demo talker"},
        {"name": "cam", "runs_on": "pi", "folder": "components/cam"},
    ],
}
URI = "http://192.168.1.10:11311"


def robot(**changes: Any) -> Robot:
    return Robot.model_validate({**ROBOT, **changes})


def master(**changes: Any) -> rosmaster.RosMaster:
    kind = discovery.for_robot(robot(**changes))
    assert isinstance(kind, rosmaster.RosMaster)
    return kind


# ------------------------------------------------------------------ the registry


@pytest.mark.parametrize("distro", ["noetic", "melodic"])
def test_a_ros1_distro_without_a_kind_gets_the_master(distro: str) -> None:
    r = robot(ros_distro=distro)
    assert r.discovery.kind is None and r.discovery_kind == "rosmaster"
    assert isinstance(discovery.for_robot(r), rosmaster.RosMaster)
    assert discovery.for_robot(r).kind == "rosmaster"


def test_the_master_is_named_explicitly_too_and_ros2_keeps_fast_dds() -> None:
    assert isinstance(discovery.for_robot(robot(discovery={"kind": "rosmaster"})), rosmaster.RosMaster)
    jazzy = discovery.for_robot(robot(ros_distro="jazzy"))  # control: a ROS 2 distro's own kind
    assert jazzy.kind == "fastdds" and not isinstance(jazzy, rosmaster.RosMaster)


# ------------------------------------------------------------------ where the master runs


def test_the_master_runs_on_the_first_host_at_port_11311() -> None:
    kind = master()
    assert [(s.index, s.host, s.address, s.port) for s in kind.servers()] == [(0, "dev", "192.168.1.10", 11311)]
    assert kind.master_uri == URI
    assert [s.host for s in kind.servers_on("dev")] == ["dev"] and kind.servers_on("pi") == []
    assert robot().discovery_servers[0].port == 11311  # the kind's default port, not Fast DDS's 11811


def test_a_servers_entry_moves_the_master_and_its_port() -> None:
    kind = master(discovery={"servers": [{"host": "pi", "port": 12000}]})
    assert [(s.host, s.address, s.port) for s in kind.servers()] == [("pi", "192.168.1.20", 12000)]
    assert kind.master_uri == "http://192.168.1.20:12000"
    assert kind.servers_on("dev") == []
    # a servers entry without a port gets the master's default
    assert master(discovery={"servers": [{"host": "pi"}]}).master_uri == "http://192.168.1.20:11311"


def test_an_ipv6_master_is_bracketed_in_its_uri() -> None:
    kind = master(discovery={"servers": [{"host": "arm"}]})
    assert kind.master_uri == "http://[fd00::20]:11311"


def test_a_dns_named_master_is_in_the_uri_as_named() -> None:
    assert master(discovery={"servers": [{"host": "nuc", "port": 11400}]}).master_uri == "http://nuc.local:11400"


# ------------------------------------------------------------------ what the master runs


def test_the_server_process_is_roscore_on_the_masters_port() -> None:
    process = master().server_process(0)
    assert process.command == ("roscore", "-p", "11311")
    assert dict(process.environment) == {"ROS_MASTER_URI": URI, **rosmaster.UNBUFFERED, "ROS_IP": "192.168.1.10"}
    assert process.state_dir is None  # the master keeps nothing across restarts


def test_the_master_runs_under_docker_init() -> None:
    """roscore (roslaunch) handles SIGTERM itself and stops its children: the init passes `docker stop` on to it
    alone, as for a component (no process-group signalling)."""
    spec = containers.discovery_spec(Project(root=Path("/srv/r1"), robot=robot()), 0)
    assert spec.docker_kwargs()["init"] is True and spec.compose_service()["init"] is True
    assert naming.INIT_SIGNALS_GROUP not in spec.env


def test_a_moved_master_runs_on_its_own_port_and_advertises_its_own_host() -> None:
    process = master(discovery={"servers": [{"host": "nuc", "port": 12000}]}).server_process(0)
    assert process.command == ("roscore", "-p", "12000")
    assert process.environment["ROS_MASTER_URI"] == "http://nuc.local:12000"
    assert process.environment["ROS_HOSTNAME"] == "nuc.local" and "ROS_IP" not in process.environment


# ------------------------------------------------------------------ what nodes and tools get


def test_a_node_on_an_ip_host_advertises_that_ip() -> None:
    assert master().client_environment("pi") == {
        "ROS_MASTER_URI": URI, **rosmaster.UNBUFFERED, "ROS_IP": "192.168.1.20"}


def test_a_node_on_a_dns_named_host_advertises_the_name() -> None:
    env = master().client_environment("nuc")
    assert env == {"ROS_MASTER_URI": URI, **rosmaster.UNBUFFERED, "ROS_HOSTNAME": "nuc.local"}


def test_a_node_on_an_ipv6_host_turns_ros_ipv6_on() -> None:
    env = master().client_environment("arm")
    assert env["ROS_IP"] == "fd00::20" and env["ROS_IPV6"] == "on" and "ROS_HOSTNAME" not in env


def test_a_bridge_container_asks_the_entrypoint_for_its_own_address() -> None:
    env = master().client_environment("dev", network_mode="bridge")
    assert env == {"ROS_MASTER_URI": URI, **rosmaster.UNBUFFERED, rosmaster.ROS_IP_FROM_CONTAINER: "1"}
    assert "ROS_IP" not in env and "ROS_HOSTNAME" not in env  # the host's address is not the container's
    assert rosmaster.ROS_IP_FROM_CONTAINER == "ROBOCORE_ROS_IP_FROM_CONTAINER"


def test_an_observer_off_the_robot_only_asks_the_master() -> None:
    env = master().observer_environment()
    assert env["ROS_MASTER_URI"] == URI
    # no address of a robot host: the tool is not on one
    assert not {"ROS_IP", "ROS_HOSTNAME", "ROS_IPV6", rosmaster.ROS_IP_FROM_CONTAINER} & set(env)
    assert set(env) <= {"ROS_MASTER_URI", "PYTHONUNBUFFERED"}


def test_an_observer_on_a_host_is_a_node_of_that_host() -> None:
    kind = master()
    assert kind.observer_environment("pi") == {"ROS_MASTER_URI": URI, **rosmaster.UNBUFFERED, "ROS_IP": "192.168.1.20"}
    assert kind.observer_environment("nuc", files=discovery.no_files)["ROS_HOSTNAME"] == "nuc.local"


def test_the_master_writes_no_files() -> None:
    kind = master()
    assert kind.files() == {}
    assert kind.observer_file is None


# ------------------------------------------------------------------ readiness

#: What roscore prints on a first start (noetic), up to the line the wait loop waits for.
ROSCORE_STARTED = (
    "... logging to /root/.ros/log/0b1c/roslaunch-dev-7.log\n"
    "Checking log directory for disk usage. This may take a while.\n"
    "Press Ctrl-C to interrupt\n"
    "Done checking log file disk usage. Usage is <1GB.\n"
    "\n"
    "started roslaunch server http://192.168.1.10:35123/\n"
    "ros_comm version 1.15.15\n"
    "\n"
    "SUMMARY\n========\n\nPARAMETERS\n * /rosdistro: noetic\n * /rosversion: 1.15.15\n\nNODES\n\n"
    "auto-starting new master\n"
    "process[master]: started with pid [25]\n"
    "ROS_MASTER_URI=http://192.168.1.10:11311/\n"
    "\n"
    "setting /run_id to 0b1c\n"
    "process[rosout-1]: started with pid [35]\n"
    "started core service [/rosout]\n"
)
PORT_TAKEN = "ERROR: Unable to start XML-RPC server, port 11311 is already in use\n"
OTHER_MASTER = ("RLException: roscore cannot run as another roscore/master is already running. \n"
                "Please kill other roscore/master processes before relaunching.\n")
RUNNING = ServerState("running")


def test_the_master_is_ready_once_rosout_runs() -> None:
    kind = master()
    assert kind.readiness(ROSCORE_STARTED, RUNNING) == READY
    assert kind.readiness("\x1b[1mstarted core service [/rosout]\x1b[0m\n", RUNNING).ready  # colours ignored


@pytest.mark.parametrize("log", ["", ROSCORE_STARTED.split("auto-starting")[0], "process[master]: started\n"])
def test_the_master_is_waiting_before_its_line(log: str) -> None:
    assert master().readiness(log, RUNNING) == WAITING
    assert master().readiness(log, ServerState("created")) == WAITING


def test_a_taken_port_fails_with_the_port_hint() -> None:
    log = ROSCORE_STARTED.split("auto-starting")[0] + "auto-starting new master\n" + PORT_TAKEN
    verdict = master().readiness(log, RUNNING)
    assert verdict.failed
    assert verdict.reason == PORT_TAKEN.strip()
    assert verdict.hint == rosmaster.PORT_HINT and "discovery.servers[0].port" in verdict.hint


def test_a_taken_port_fails_even_after_the_ready_line() -> None:
    """rosout started on a master that already ran there: the port line says this roscore does not serve."""
    assert master().readiness(ROSCORE_STARTED + PORT_TAKEN, RUNNING).failed
    assert master().readiness(PORT_TAKEN + ROSCORE_STARTED, RUNNING).failed  # before the ready line too


def test_another_master_on_the_port_fails() -> None:
    verdict = master().readiness(OTHER_MASTER, ServerState("exited"))
    assert verdict.failed and verdict.hint == rosmaster.PORT_HINT


@pytest.mark.parametrize("state", [ServerState("exited"), ServerState("dead"), ServerState("restarting"),
                                   ServerState("running", restart_count=1), ServerState("running", timed_out=True)])
def test_a_stopped_restarted_or_late_master_fails(state: ServerState) -> None:
    verdict = master().readiness("auto-starting new master\n", state)
    assert verdict.failed and verdict.reason == "auto-starting new master"
    assert verdict.hint == rosmaster.PORT_HINT


def test_a_restarted_master_fails_though_its_first_start_logged_ready() -> None:
    assert master().readiness(ROSCORE_STARTED, ServerState("running", restart_count=1)).failed
    assert master().readiness(ROSCORE_STARTED, ServerState("running", restart_count=0)).ready  # control


def test_a_silent_late_master_says_no_output() -> None:
    assert master().readiness("", ServerState("running", timed_out=True)).reason == "no output"


# ------------------------------------------------------------------ listing nodes


def test_nodes_are_listed_with_rosnode_behind_the_entrypoint() -> None:
    assert master().node_list_argv(3.0) == [naming.ENTRYPOINT, "rosnode", "list"]


def test_rosnode_list_output_gives_the_node_names() -> None:
    kind = master()
    assert kind.nodes_from_output("/listener\n/rosout\n/talker\n") == ["/listener", "/rosout", "/talker"]
    assert kind.nodes_from_output("ERROR: Unable to communicate with master!\n") == []


# ------------------------------------------------------------------ containers


def project(**changes: Any) -> Project:
    return Project(root=Path("/srv/myrobot"), robot=robot(**changes))


def test_the_master_container_runs_roscore_in_the_base_image_on_the_host_network() -> None:
    dev = {s.service: s for s in containers.host_specs(project(), "dev")}
    assert list(dev) == ["discovery-0", "talker"]
    server = dev["discovery-0"]
    assert server.command == ("roscore", "-p", "11311")
    assert server.entrypoint == (naming.ENTRYPOINT,) and server.image == "myrobot-base:latest"
    assert server.network_mode == "host"
    assert server.env == {"ROS_MASTER_URI": URI, **rosmaster.UNBUFFERED, "ROS_IP": "192.168.1.10"}
    assert server.mounts == ()  # no state volume
    assert containers.state_volumes(project(), "dev") == []


def test_components_are_clients_of_the_master() -> None:
    p = project()
    talker = {s.service: s for s in containers.host_specs(p, "dev")}["talker"]
    assert talker.env["ROS_MASTER_URI"] == URI and talker.env["ROS_IP"] == "192.168.1.10"
    assert talker.depends_on == ("discovery-0",)
    assert not any(key.startswith(("FASTDDS", "ROS_DISCOVERY", "RMW_")) for key in talker.env)
    (cam,) = containers.host_specs(p, "pi")  # no master on pi: only the component
    assert cam.env["ROS_MASTER_URI"] == URI and cam.env["ROS_IP"] == "192.168.1.20"
    assert cam.depends_on == ()


def test_a_moved_master_starts_on_its_host() -> None:
    p = project(discovery={"servers": [{"host": "pi", "port": 12000}]})
    assert [s.service for s in containers.host_specs(p, "pi")] == ["discovery-0", "cam"]
    assert [s.service for s in containers.host_specs(p, "dev")] == ["talker"]
    assert {s.service: s for s in containers.host_specs(p, "dev")}["talker"].env["ROS_MASTER_URI"] == (
        "http://192.168.1.20:12000")


def test_a_bridge_component_on_a_one_host_robot_gets_its_own_address_at_start() -> None:
    hosts = [{"name": "dev", "ip": "127.0.0.1", "docker": "local"}]
    comps = [{"name": "web", "runs_on": "dev", "folder": "components/web", "ports": ["8080:80"]}]
    p = project(hosts=hosts, components=comps)
    web = {s.service: s for s in containers.host_specs(p, "dev")}["web"]
    assert web.network_mode == "bridge"
    assert web.env["ROBOCORE_ROS_IP_FROM_CONTAINER"] == "1" and "ROS_IP" not in web.env
    # the container's loopback is its own: it reaches the master on its host through the gateway
    assert web.env["ROS_MASTER_URI"] == "http://host.docker.internal:11311"
    master_spec = {s.service: s for s in containers.host_specs(p, "dev")}["discovery-0"]
    assert master_spec.env["ROS_MASTER_URI"] == "http://127.0.0.1:11311"  # the master itself is on the host


def test_the_compose_file_runs_roscore_and_declares_no_volume() -> None:
    document = yaml.safe_load(compose.render(project(), "dev"))
    assert document["services"]["discovery-0"]["command"] == ["roscore", "-p", "11311"]
    assert document["services"]["discovery-0"]["network_mode"] == "host"
    assert "volumes" not in document or not document["volumes"]


# ------------------------------------------------------------------ the entrypoint's bridge block


def _bridge_block() -> str:
    """The entrypoint's ROBOCORE_ROS_IP_FROM_CONTAINER block (it sits after the sourcing, before the exec)."""
    text = resources.read("entrypoint.sh").decode()
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if "ROBOCORE_ROS_IP_FROM_CONTAINER" in line)
    end = lines.index('exec "$@"')
    assert start < end and start > next(i for i, line in enumerate(lines) if "local_setup.bash" in line)
    return "\n".join(lines[start:end]) + "\n"


def _run_block(tmp_path: Path, env: dict[str, str]) -> dict[str, str]:
    """The bridge block run by bash with a fake ``hostname`` that prints two addresses, then the exported env."""
    fake = tmp_path / "bin"
    fake.mkdir(exist_ok=True)
    (fake / "hostname").write_text("#!/bin/sh\n[ \"$1\" = -i ] && echo '172.18.0.5 fd00::5'\n")
    (fake / "hostname").chmod(0o755)
    script = "set -eu\n" + _bridge_block() + 'exec env\n'
    done = subprocess.run(["bash", "-c", script], env={"PATH": f"{fake}:/usr/bin:/bin", **env},
                          capture_output=True, text=True, check=True)
    return dict(line.split("=", 1) for line in done.stdout.splitlines() if "=" in line)


def test_the_entrypoint_exports_the_containers_first_address(tmp_path: Path) -> None:
    out = _run_block(tmp_path, {"ROBOCORE_ROS_IP_FROM_CONTAINER": "1"})
    assert out["ROS_IP"] == "172.18.0.5"


def test_the_entrypoint_keeps_an_address_given_to_the_node(tmp_path: Path) -> None:
    assert _run_block(tmp_path, {"ROBOCORE_ROS_IP_FROM_CONTAINER": "1", "ROS_IP": "10.0.0.9"})["ROS_IP"] == "10.0.0.9"
    named = _run_block(tmp_path, {"ROBOCORE_ROS_IP_FROM_CONTAINER": "1", "ROS_HOSTNAME": "cam.local"})
    assert "ROS_IP" not in named and named["ROS_HOSTNAME"] == "cam.local"


def test_the_entrypoint_sets_no_address_without_the_flag(tmp_path: Path) -> None:
    assert "ROS_IP" not in _run_block(tmp_path, {})
    assert "ROS_IP" not in _run_block(tmp_path, {"ROBOCORE_ROS_IP_FROM_CONTAINER": ""})


def test_the_entrypoint_is_still_valid_bash() -> None:
    path = Path(resources.__file__).parent / "entrypoint.sh"
    assert subprocess.run(["bash", "-n", str(path)], capture_output=True).returncode == 0
    assert os.access(path, os.X_OK)
