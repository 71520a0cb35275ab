"""The isolated test run as data: host namespaces, names, labels, discovery addresses (no Docker)."""

from __future__ import annotations

from pathlib import Path

import pytest

from robocore.plan import naming, testrun
from robocore.plan.discovery import fastdds as dds
from robocore.plan.testrun import TestRun
from robocore.project import Project

TWO_HOSTS = """\
ros_distro: jazzy
image_prefix: demo-
base: {kind: wheels}
discovery:
  servers: [{host: main, port: 11811}]
hosts:
  - {name: main, ip: 192.168.1.10, user: robot}
  - {name: arm, ip: 192.168.1.11, user: robot}
  - {name: spare, ip: 192.168.1.12, user: robot}
components:
  - {name: talker, folder: components/talker, runs_on: main, entrypoint: ros2 run demo_talker talker}
  - {name: listener, folder: components/listener, runs_on: arm, entrypoint: ros2 run demo_listener listener,
     ports: ["8080:80"]}
"""

RUN = TestRun(project="demo", run_id="0123abcd", domain_id=42, owner="vm|boot|1|2")
ADDRESSES = {"main": "172.30.0.2", "arm": "172.30.0.3"}


@pytest.fixture
def project(make_project) -> Project:  # type: ignore[no-untyped-def]
    root = make_project(TWO_HOSTS, folders=("components/talker", "components/listener"), name="demo")
    source = Project.load(root)
    return Project(root=source.root, robot=testrun.isolated_robot(source.robot, ADDRESSES, RUN.domain_id))


def test_only_hosts_in_use_become_namespaces(make_project) -> None:  # type: ignore[no-untyped-def]
    root = make_project(TWO_HOSTS, folders=("components/talker", "components/listener"), name="demo")
    assert testrun.hosts_to_start(Project.load(root).robot) == ["main", "arm"]


def test_isolated_hosts_are_local_at_their_run_address_in_the_runs_domain(project: Project) -> None:
    robot = project.robot
    assert [(h.name, h.ip, h.is_local) for h in robot.hosts] == [
        ("main", "172.30.0.2", True), ("arm", "172.30.0.3", True), ("spare", "192.168.1.12", False)]
    assert robot.ros_domain_id == 42
    assert dds.discovery_server_value(robot) == "172.30.0.2:11811"


def test_components_join_their_hosts_namespaces_with_the_runs_profiles(project: Project) -> None:
    specs = testrun.component_specs(RUN, project, "/tmp/run/dds")
    talker, listener = specs["talker"], specs["listener"]
    assert talker.name == "demo-t0123abcd-talker"
    assert talker.network_mode == "container:demo-t0123abcd-host-main"
    assert talker.ipc_mode == "container:demo-t0123abcd-host-main"  # shm: components of a host share memory
    assert listener.network_mode == "container:demo-t0123abcd-host-arm"
    assert listener.ports == ()  # published ports mean nothing inside a namespace container
    assert talker.restart == "no"
    mounts = {m.target: m.source for m in talker.mounts}
    assert mounts[naming.CONTAINER_DDS] == "/tmp/run/dds"
    assert mounts[naming.CONTAINER_INSTALL] == str(project.build_dir("talker") / "install")
    assert talker.env["ROS_DISCOVERY_SERVER"] == "172.30.0.2:11811"
    assert talker.env["ROS_DOMAIN_ID"] == "42"
    labels = talker.labels
    assert labels[testrun.LABEL_RUN] == "0123abcd" and labels[testrun.LABEL_OWNER] == "vm|boot|1|2"
    assert labels[naming.LABEL_PROJECT] == "demo-test-0123abcd"  # never the robot's own: down/status skip it


def test_udp_robots_keep_private_ipc(make_project) -> None:  # type: ignore[no-untyped-def]
    root = make_project(TWO_HOSTS.replace("servers: [{host: main, port: 11811}]",
                                          "servers: [{host: main, port: 11811}]\n  transport: udp"),
                        folders=("components/talker", "components/listener"), name="demo")
    source = Project.load(root)
    project = Project(root=source.root, robot=testrun.isolated_robot(source.robot, ADDRESSES, 7))
    assert testrun.component_specs(RUN, project, "/d")["talker"].ipc_mode is None


def test_servers_run_in_their_host_with_a_state_volume_of_the_run(project: Project) -> None:
    (server,) = testrun.server_specs(RUN, project, "/tmp/run/dds")
    assert server.name == "demo-t0123abcd-discovery-0"
    assert server.network_mode == "container:demo-t0123abcd-host-main"
    assert [(m.source, m.target) for m in server.mounts] == [
        ("demo-t0123abcd-discovery-0-state", "/robocore/discovery")]
    assert server.command is not None and "11811" in server.command


def test_host_containers_hold_the_namespaces_on_the_runs_network(project: Project) -> None:
    spec = testrun.host_spec(RUN, project, "arm")
    assert spec.name == "demo-t0123abcd-host-arm"
    assert spec.network_mode == "demo-t0123abcd-net"
    assert spec.ipc_mode == "shareable"
    assert spec.image == "demo-base:latest"
    assert (spec.entrypoint, spec.command) == (("sleep",), ("infinity",))


def test_the_probe_is_a_udp_super_client_with_its_own_profile(project: Project) -> None:
    env = testrun.probe_environment(project.robot, "/tmp/run/probe.xml")
    assert env["ROS_SUPER_CLIENT"] == "TRUE"
    assert env["FASTDDS_BUILTIN_TRANSPORTS"] == "UDPv4"
    assert env["FASTRTPS_DEFAULT_PROFILES_FILE"] == "/tmp/run/probe.xml"
    assert env["ROS_DISCOVERY_SERVER"] == "172.30.0.2:11811"  # read for each new participant
    xml = testrun.probe_profile(project.robot)
    # nothing of this robot in the file: the process reads it once, and a later robot's node must not use it
    assert "discoveryProtocol" not in xml and "172.30.0.2" not in xml and "RemoteServer" not in xml
    assert "<clientAnnouncementPeriod>" in xml


def test_names_of_two_runs_never_collide() -> None:
    other = TestRun(project="demo", run_id="ffff0000", domain_id=43, owner="x")
    assert RUN.network != other.network
    assert RUN.component_container("talker") != other.component_container("talker")
    assert RUN.server_volume(0) != other.server_volume(0)


def test_find_project_walks_up(tmp_path: Path) -> None:
    from robocore.testing.plugin import find_project

    (tmp_path / "robot.yaml").write_text("ros_distro: jazzy\n")
    deep = tmp_path / "tests" / "graph"
    deep.mkdir(parents=True)
    assert find_project(deep) == tmp_path
    sibling = tmp_path.parent / f"{tmp_path.name}-elsewhere"
    sibling.mkdir()
    assert find_project(sibling) is None


ALL_ARM64 = """\
ros_distro: noetic
image_prefix: demo-
base: {kind: debian}
hosts:
  - {name: pi, ip: 192.168.1.20, arch: arm64}
components:
  - {name: talker, folder: components/talker, runs_on: pi}
"""


def test_a_run_of_a_robot_with_no_host_of_this_machines_arch_uses_the_base_of_its_hosts(make_project) -> None:  # type: ignore[no-untyped-def]
    """One arm64 host, tested on an amd64 machine: its namespace holder and its master run the arm64 base, the
    one base prepare-base made (there is no ``demo-base:latest``)."""
    root = make_project(ALL_ARM64, folders=("components/talker",), name="demo")
    source = Project.load(root)
    project = Project(root=source.root, robot=testrun.isolated_robot(source.robot, {"pi": "172.30.0.2"}, 7),
                      native_arch="amd64")
    assert testrun.host_spec(RUN, project, "pi").image == "demo-base:latest-arm64"
    [server] = testrun.server_specs(RUN, project, "/tmp/dds")
    assert server.image == "demo-base:latest-arm64"
