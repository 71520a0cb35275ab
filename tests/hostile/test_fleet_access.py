"""fleet.yaml's Docker access and addresses get robot.yaml's defences (the fourth hostile pass).

The manager, and each robot's hosts as merged with robot.yaml's, go through robot.yaml's host checks and risks,
one ``fleet.yaml:LINE: key`` line each; addresses that name no one machine are refused in both files, and an
IPv4-mapped address is compared as the IPv4 address it is; a fleet dry run contacts nothing and says how the
manager is reached.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from corpus import FLEET_ROBOT_YAML
from in_process import run_main

from robocore.adapters import docker_hosts, page_server

ROBOT_YAML = FLEET_ROBOT_YAML


def fleet(manager: str = "{ip: 10.0.0.2}", r1: str = "{ip: 10.0.1.5}", r2: str = "{ip: 10.0.1.6}") -> str:
    return f"manager: {manager}\nrobots:\n  - name: r1\n    hosts:\n      main: {r1}\n" \
           f"  - name: r2\n    hosts:\n      main: {r2}\n"


def validate(tmp_path: Path, fleet_text: str, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
             robot_text: str = ROBOT_YAML) -> tuple[int, list[str], str]:
    root = tmp_path / "project"
    root.mkdir(exist_ok=True)
    (root / "robot.yaml").write_text(robot_text)
    (root / "fleet.yaml").write_text(fleet_text)
    monkeypatch.chdir(root)
    monkeypatch.setenv("DOCKER_HOST", f"unix://{tmp_path}/no-docker.sock")
    monkeypatch.setattr(sys, "argv", ["robocore", "-p", str(root), "validate"])
    code, out, err = run_main(["-p", str(root), "validate"], capsys)
    assert "Traceback" not in err
    assert all(line.isprintable() and len(line) < 500 for line in err.splitlines())
    return code, [line for line in err.splitlines() if line.startswith("error: ")], out + err


REFUSED = {
    # the cases
    "manager-plain-tcp": (fleet(manager="{ip: 10.0.0.2, docker: tcp}"),
                          "error: fleet.yaml:1: manager.docker: plain TCP"),
    "manager-tls-without-files": (fleet(manager="{ip: 10.0.0.2, docker: tls}"),
                                  "error: fleet.yaml:1: manager.docker: docker: tls needs tls"),
    "manager-tls-file-outside": (fleet(manager="{ip: 10.0.0.2, docker: tls, tls: {ca_cert: ../outside/ca.pem, "
                                       "client_cert: c.pem, client_key: k.pem}}"),
                                 "error: fleet.yaml:1: manager.tls.ca_cert: file '../outside/ca.pem' names a file "
                                 "outside the project folder"),
    "robot-host-tcp": (fleet(r2="{ip: 10.0.1.6, docker: tcp}"), "error: fleet.yaml:8: robots[1].hosts.main.docker: "
                       "plain TCP"),
    "robot-host-tls-never-connects": (fleet(r1="{ip: 10.0.1.5, docker: tls}"),
                                      "error: fleet.yaml:5: robots[0].hosts.main.docker: docker: tls needs tls"),
    "manager-docker-port-on-ssh": (fleet(manager="{ip: 10.0.0.2, docker_port: 2375}"),
                                   "error: fleet.yaml:1: manager.docker_port: docker_port only applies"),
    "manager-insecure-on-ssh": (fleet(manager="{ip: 10.0.0.2, insecure: true}"),
                                "error: fleet.yaml:1: manager.insecure: insecure: true only applies to docker: tcp"),
    # variants
    "robot-docker-port-on-ssh": (fleet(r2="{ip: 10.0.1.6, docker: ssh, docker_port: 2376}"),
                                 "error: fleet.yaml:8: robots[1].hosts.main.docker_port: docker_port only applies"),
    "manager-tls-files-on-tcp": (fleet(manager="{ip: 10.0.0.2, docker: tcp, insecure: true, tls: {ca_cert: a, "
                                       "client_cert: b, client_key: c}}"),
                                 "error: fleet.yaml:1: manager.tls: tls files given but docker is 'tcp'"),
    # item 6: addresses that name no machine, and one address written twice
    "robot-unspecified": (fleet(r1='{ip: "0.0.0.0"}'), "error: fleet.yaml:5: robots[0].hosts.main.ip: 0.0.0.0 is the "
                          "unspecified address"),
    "robot-unspecified-ipv6": (fleet(r1='{ip: "::"}'), "error: fleet.yaml:5: robots[0].hosts.main.ip: :: is the "
                               "unspecified address"),
    "robot-mapped-loopback": (fleet(r1='{ip: "::ffff:127.0.0.1"}'), "error: fleet.yaml:5: robots[0].hosts.main.ip: "
                              "::ffff:127.0.0.1 is the loopback address 127.0.0.1"),
    "manager-mapped-loopback": (fleet(manager='{ip: "::ffff:127.0.0.9"}'), "error: fleet.yaml:1: manager.ip: "
                                "::ffff:127.0.0.9 is the loopback address"),
    "manager-unspecified": (fleet(manager='{ip: "0.0.0.0"}'), "error: fleet.yaml:1: manager.ip: 0.0.0.0 is the "
                            "unspecified"),
    "mapped-duplicate": (fleet(r1='{ip: "192.0.2.5"}', r2='{ip: "::ffff:192.0.2.5"}'),
                         "error: fleet.yaml:8: robots[1].hosts.main.ip: address '::ffff:192.0.2.5' is also "
                         "robots[0].hosts.main"),
    "mapped-duplicate-hex": (fleet(r1='{ip: "::ffff:c000:205"}', r2='{ip: "192.0.2.5"}'),
                             "error: fleet.yaml:8: robots[1].hosts.main.ip: address '192.0.2.5' is also"),
    # IPv4 addresses written as numbers, which resolvers read (inet_aton): loopback, "any", one address twice
    "robot-hex-loopback": (fleet(r1='{ip: "0x7f000001"}'), "error: fleet.yaml:5: robots[0].hosts.main.ip: must be "
                           "an IP address or a host name; '0x7f000001' is an IPv4 address written as numbers, which "
                           "ssh and Docker read as 127.0.0.1"),
    "robot-hex-any": (fleet(r1='{ip: "0x0"}'), "error: fleet.yaml:5: robots[0].hosts.main.ip: must be an IP address "
                      "or a host name; '0x0' is an IPv4 address written as numbers, which ssh and Docker read as "
                      "0.0.0.0"),
    "manager-dotted-hex-loopback": (fleet(manager='{ip: "127.0.0.0x1"}'), "error: fleet.yaml:1: manager.ip: must be"),
    # names of this machine: /etc/hosts's for ::1, and every name under localhost (RFC 6761)
    "robot-ip6-loopback": (fleet(r1="{ip: ip6-loopback}"), "error: fleet.yaml:5: robots[0].hosts.main.ip: "
                           "'ip6-loopback' is a loopback address"),
    "robot-under-localhost": (fleet(r2="{ip: robot2.localhost}"), "error: fleet.yaml:8: robots[1].hosts.main.ip: "
                              "'robot2.localhost' is a loopback address"),
    "hex-duplicate": (fleet(r1='{ip: "192.0.2.5"}', r2='{ip: "0xc0000205"}'),
                      "error: fleet.yaml:8: robots[1].hosts.main.ip: must be an IP address or a host name; "
                      "'0xc0000205' is an IPv4 address written as numbers, which ssh and Docker read as 192.0.2.5"),
}


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_fleet_docker_access_and_addresses_are_checked_like_robot_yaml(
        case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    text, start = REFUSED[case]
    if case == "manager-tls-file-outside":
        (tmp_path / "outside").mkdir()
        (tmp_path / "outside" / "ca.pem").write_text("x")
    code, errors, _ = validate(tmp_path, text, capsys, monkeypatch)
    assert code == 2
    assert any(line.startswith(start) for line in errors), errors


def test_negative_control_good_access_validates(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    root = tmp_path / "project"
    (root / "certs").mkdir(parents=True)
    for name in ("ca.pem", "cert.pem", "key.pem"):
        (root / "certs" / name).write_text("x")
    text = fleet(manager="{ip: 10.0.0.2, docker: tls, tls: {ca_cert: certs/ca.pem, client_cert: certs/cert.pem, "
                         "client_key: certs/key.pem}}", r1='{ip: "::ffff:192.0.2.5", docker: ssh}',
                 r2="{ip: 0xdead.robots.example}")  # a name whose first label reads like hex is a name
    code, errors, said = validate(tmp_path, text, capsys, monkeypatch)
    assert code == 0 and not errors, said


def test_an_insecure_manager_is_one_warning_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    code, errors, said = validate(tmp_path, fleet(manager="{ip: 10.0.0.2, docker: tcp, insecure: true}"), capsys,
                                  monkeypatch)
    assert code == 0 and not errors, said
    warnings = [line for line in said.splitlines() if "warning:" in line]
    assert len(warnings) == 1 and warnings[0].startswith("fleet.yaml:1: manager.insecure: warning: "), warnings


@pytest.mark.parametrize("address, says", [("0.0.0.0", "unspecified"), ("::", "unspecified"),
                                           ("::ffff:127.0.0.1", "loopback address 127.0.0.1"),
                                           ("::ffff:0.0.0.0", "unspecified"),
                                           ("0x7f000001", "read as 127.0.0.1"), ("0x7f.1", "read as 127.0.0.1"),
                                           ("0xc0a8010a", "read as 192.168.1.10")])
def test_robot_yaml_refuses_the_same_addresses(address: str, says: str, tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str],
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    root = tmp_path / "project"
    root.mkdir()
    (root / "robot.yaml").write_text(ROBOT_YAML.replace("192.168.1.10", f'"{address}"'))
    monkeypatch.chdir(root)
    code, _, err = run_main(["-p", str(root), "validate"], capsys)
    errors = [line for line in err.splitlines() if line.startswith("error: ")]
    assert code == 2 and len(errors) == 1 and errors[0].startswith("error: robot.yaml:4: hosts[0].ip: "), err
    assert says in errors[0]


# --- item 7: a fleet dry run contacts nothing ----------------------------------------------------------------------

@pytest.mark.parametrize("verb", [["status"], ["rollback"], ["rollback", "r1"], ["join"],
                                  ["logs", "r1"], ["logs", "r1", "--component", "talker"], ["connect", "r1", "talker"],
                                  ["page", "--out", "snapshot"], ["page", "--serve"],
                                  ["page", "--serve", "--port", "0", "--bind", "0.0.0.0"]])
def test_a_fleet_dry_run_contacts_no_manager(verb: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    contacted: list[str] = []

    def refuse(host: object, *args: object, **kwargs: object) -> object:
        contacted.append(str(host))
        raise AssertionError("a dry run contacted the manager")

    monkeypatch.setattr(docker_hosts, "client_for", refuse)
    monkeypatch.setattr(page_server, "start", refuse)  # nor serves anything
    root = tmp_path / "project"
    root.mkdir()
    (root / "robot.yaml").write_text(ROBOT_YAML)
    (root / "fleet.yaml").write_text(fleet(manager="{ip: 10.0.0.2, user: ops}"))
    monkeypatch.chdir(root)
    code, out, err = run_main(["-p", str(root), "fleet", *verb, "--dry-run"], capsys)
    assert not contacted
    assert code == 0, err
    assert "manager 10.0.0.2: docker via ssh://ops@10.0.0.2:22 (dry run: not contacted)" in out + err
    assert sorted(p.name for p in root.iterdir()) == ["fleet.yaml", "robot.yaml"]  # nothing written


def test_a_page_dry_run_refuses_the_folder_the_real_page_refuses(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    root = tmp_path / "project"
    root.mkdir()
    (root / "robot.yaml").write_text(ROBOT_YAML)
    (root / "fleet.yaml").write_text(fleet())
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "elsewhere")
    monkeypatch.chdir(root)
    code, out, err = run_main(["-p", str(root), "fleet", "page", "--out", str(tmp_path / "link"), "--dry-run"], capsys)
    errors = [line for line in err.splitlines() if line.startswith("error: ")]
    assert code == 2 and len(errors) == 1 and "is a symlink" in errors[0] and "would" not in out + err, err


def test_negative_control_a_real_fleet_status_asks_the_manager(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    from robocore.errors import HostError

    contacted: list[str] = []

    def refuse(host: object, *args: object, **kwargs: object) -> object:
        contacted.append(str(host))
        raise HostError("manager: unreachable (test)")

    monkeypatch.setattr(docker_hosts, "client_for", refuse)
    root = tmp_path / "project"
    root.mkdir()
    (root / "robot.yaml").write_text(ROBOT_YAML)
    (root / "fleet.yaml").write_text(fleet())
    monkeypatch.chdir(root)
    code, _, _ = run_main(["-p", str(root), "fleet", "status"], capsys)
    assert contacted and code != 0


def test_a_robots_own_domain_in_the_ephemeral_range_is_one_warning_line(tmp_path: Path,
                                                                         capsys: pytest.CaptureFixture[str],
                                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """robot.yaml's ros_domain_id above 101 is a warning (its DDS ports fall among Linux's ephemeral ports); a
    fleet robot's own ``ros_domain_id`` is the same risk and gets the same line, on fleet.yaml's line."""
    text = fleet().replace("  - name: r2\n", "  - name: r2\n    ros_domain_id: 150\n")
    assert "ros_domain_id: 150" in text
    code, _, said = validate(tmp_path, text, capsys, monkeypatch)
    assert code == 0, said
    warnings = [line for line in said.splitlines() if "warning:" in line]
    assert len(warnings) == 1, warnings
    assert "robots[1].ros_domain_id: warning: ROS domain 150 binds its DDS ports from 44900" in warnings[0]
    assert warnings[0].startswith("fleet.yaml:")
    # negative control: a domain of 0-101 warns nothing
    code, _, said = validate(tmp_path, text.replace("150", "101"), capsys, monkeypatch)
    assert code == 0 and "warning:" not in said, said
