"""The robot.yaml model's derived values, which every later stage reads."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from robocore.config.checks import check_port, did_you_mean
from robocore.config.loader import format_path, parse_robot_text
from robocore.config.model import DockerAccess, Host, Robot, is_loopback_address
from robocore.errors import ConfigError


def host(**fields: object) -> Host:
    return Host.model_validate({"name": "h", "ip": "10.0.0.5", **fields})


@pytest.mark.parametrize(
    "ip, docker, access",
    [
        ("127.0.0.1", None, DockerAccess.local),
        ("localhost", None, DockerAccess.local),
        ("::1", None, DockerAccess.local),
        ("10.0.0.5", None, DockerAccess.ssh),
        ("pi5.local", None, DockerAccess.ssh),
        ("10.0.0.5", "local", DockerAccess.local),
        ("10.0.0.5", "tls", DockerAccess.tls),
        ("127.0.0.1", "ssh", DockerAccess.ssh),
    ],
)
def test_host_access(ip: str, docker: str | None, access: DockerAccess) -> None:
    h = host(ip=ip, docker=docker)
    assert h.access is access
    assert h.is_local is (access is DockerAccess.local)


@pytest.mark.parametrize(
    "address, loopback",
    [
        ("127.0.0.1", True),
        ("127.1.2.3", True),
        ("::1", True),
        ("[::1]", True),
        ("localhost", True),
        ("LOCALHOST", True),
        ("10.0.0.1", False),
        ("pi5.local", False),
        ("0.0.0.0", False),
        ("fe80::1", False),
    ],
)
def test_loopback_addresses(address: str, loopback: bool) -> None:
    assert is_loopback_address(address) is loopback


@pytest.mark.parametrize(
    "user, mount_root, root",
    [
        ("root", None, "/root/robocore"),
        ("robot", None, "/home/robot/robocore"),
        ("robot", "/srv/robocore/", "/srv/robocore"),
        ("robot", "/srv/robocore", "/srv/robocore"),
    ],
)
def test_deploy_root(user: str, mount_root: str | None, root: str) -> None:
    assert host(user=user, mount_root=mount_root).deploy_root == root


@pytest.mark.parametrize("mount_root", ["/", "//", "relative", "/srv/../etc", "/srv//x", "/srv/./x", "/srv/x\n",
                                        "/srv/$(id)", "/srv/a b"])
def test_mount_root_is_a_normalised_folder_below_the_root(mount_root: str) -> None:
    with pytest.raises(ValidationError):
        host(mount_root=mount_root)


def test_models_are_frozen_and_reject_unknown_keys() -> None:
    h = host()
    with pytest.raises(ValidationError):
        h.ip = "1.2.3.4"  # type: ignore[misc]
    with pytest.raises(ValidationError):
        host(colour="red")


ROBOT = """\
ros_distro: kilted
hosts:
  - {name: a, ip: 10.0.0.1}
  - {name: b, ip: 10.0.0.2}
components:
  - {name: one, runs_on: a, ports: ['8080:80']}
  - {name: two, runs_on: b, network: host}
  - {name: three, runs_on: a, ports: ['1:1'], network: host, environment: {N: 1, F: 1.5, B: true, S: x}}
"""


VALID = ROBOT.replace(", ports: ['1:1'], network: host", "")


def robot(text: str = VALID) -> Robot:
    return parse_robot_text(text)


def test_robot_lookups_and_defaults() -> None:
    r = robot()
    assert r.host("b").ip == "10.0.0.2"
    assert r.component("two").runs_on == "b"
    with pytest.raises(KeyError):
        r.host("c")
    with pytest.raises(KeyError):
        r.component("four")
    assert [c.name for c in r.components_on("a")] == ["one", "three"]
    assert r.components_on("nowhere") == []
    assert r.ros_domain_id == 0 and r.image_prefix == "" and r.registry is None
    assert r.base.kind.value == "official"
    assert [(s.host, s.port) for s in r.discovery_servers] == [("a", 11811)]
    assert r.discovery.transport == "shm"
    assert r.fastdds_line == 3
    assert r.component("one").network_mode == "bridge"
    assert r.component("two").network_mode == "host"
    assert r.component("three").environment == {"N": "1", "F": "1.5", "B": "true", "S": "x"}
    assert r.component("three").restart == "unless-stopped"


def test_ports_with_explicit_host_network_are_refused() -> None:
    with pytest.raises(ConfigError) as caught:
        robot(ROBOT)
    assert caught.value.lines() == [
        "robot.yaml:8: components[2].ports: ports are ignored with network: host; remove them or use network: bridge"
    ]


@pytest.mark.parametrize("distro, line", [("humble", 2), ("jazzy", 2), ("kilted", 3), ("rolling", 3)])
def test_fastdds_line_per_distro(distro: str, line: int) -> None:
    assert robot(VALID.replace("kilted", distro)).fastdds_line == line


@pytest.mark.parametrize(
    "port, ok",
    [
        ("80:80", True),
        ("127.0.0.1:8080:80/udp", True),
        ("8000-8002:9000-9002", True),
        ("[::1]:53:53/udp", True),
        ("0:80", False),
        ("80", False),
        ("a:b", False),
        ("9000-8000:1-2", False),
        ("80:80/icmp", False),
    ],
)
def test_port_mappings(port: str, ok: bool) -> None:
    assert (check_port(port) is None) is ok


def test_key_paths_render_like_the_file() -> None:
    assert format_path(("components", 0, "runs_on")) == "components[0].runs_on"
    assert format_path(("components", 1, "environment", "MY VAR")) == "components[1].environment['MY VAR']"
    assert format_path(("hosts", 0, True)) == "hosts[0][True]"
    assert format_path(()) == ""


def test_did_you_mean() -> None:
    assert did_you_mean("rpi6", ["rpi5", "jetson"]) == "; did you mean 'rpi5'?"
    assert did_you_mean("xyz", ["rpi5", "jetson"]) == ""


def test_a_loopback_discovery_server_is_fine_while_remote_hosts_run_nothing() -> None:
    text = """\
ros_distro: jazzy
hosts:
  - {name: dev, ip: 127.0.0.1}
  - {name: spare, ip: 10.0.0.9}
components:
  - {name: talker, runs_on: dev, image: busybox}
"""
    assert parse_robot_text(text).host("spare").ip == "10.0.0.9"
    with pytest.raises(ConfigError) as caught:
        parse_robot_text(text.replace("runs_on: dev", "runs_on: spare"))
    assert caught.value.lines() == [
        "robot.yaml:3: hosts[0].ip: the discovery server runs on the first host by default, but '127.0.0.1' is a "
        "loopback address that remote hosts (spare) cannot reach; give dev its LAN address, list a remote host first, "
        "or set discovery.servers"]
