"""The fleet plan: each robot as its own robot.yaml, the waves of a rollout (golden), and what Swarm refuses."""

from __future__ import annotations

from pathlib import Path

import pytest
from golden_files import check_golden

from robocore.config.fleet import Fleet, parse_fleet_text
from robocore.config.loader import parse_robot_text
from robocore.config.model import Robot
from robocore.plan.fleet import fleet_instances, plan_waves, robot_instance, swarm_problems, swarm_refusals

ROBOT = """\
ros_distro: jazzy
ros_domain_id: 7
hosts:
  - {name: main, ip: 127.0.0.1, user: me}
  - {name: arm, ip: 127.0.0.1, arch: arm64, ssh_port: 2200}
components:
  - {name: talker, folder: components/talker, runs_on: main}
  - {name: listener, folder: components/listener, runs_on: arm}
"""


def fleet_of(count: int, waves: str, robot: Robot, labels: dict[int, str] | None = None) -> Fleet:
    lines = ["manager: {ip: 10.0.0.2}", "registry: 10.0.0.2:5000", "robots:"]
    for i in range(1, count + 1):
        label = (labels or {}).get(i, "a")
        lines.append(f"  - {{name: r{i}, labels: {{site: {label}}}, hosts: {{main: {{ip: 10.1.{i}.1}}, "
                     f"arm: {{ip: 10.1.{i}.2}}}}}}")
    return parse_fleet_text("\n".join(lines) + "\nrollout:\n  waves:\n" + waves, robot)


@pytest.fixture(scope="module")
def robot() -> Robot:
    return parse_robot_text(ROBOT)


def test_robot_instance_applies_the_robots_addresses_users_ports_and_domain(robot: Robot) -> None:
    fleet = parse_fleet_text("""\
manager: {ip: 10.0.0.2}
registry: 10.0.0.2:5000
robots:
  - name: r1
    hosts:
      main: {ip: 10.0.1.5, user: root, ssh_port: 2022}
      arm: {ip: r1-arm.lan, docker: ssh}
    ros_domain_id: 3
  - {name: r2, hosts: {main: {ip: 10.0.2.5}, arm: {ip: 10.0.2.6}}}
""", robot)
    one = robot_instance(robot, fleet.robot("r1"), registry=fleet.registry_for(robot))
    main, arm = one.hosts
    assert (main.ip, main.user, main.ssh_port, main.access.value) == ("10.0.1.5", "root", 2022, "ssh")
    # (docker: tls here would never connect: robot.yaml's arm host has no TLS files; fleet.yaml refuses it)
    assert (arm.ip, arm.user, arm.ssh_port, arm.access.value, arm.docker_port) == ("r1-arm.lan", "root", 2200,
                                                                                   "ssh", None)
    assert arm.arch.value == "arm64" and not main.is_local  # robot.yaml's local dev machine is a robot host here
    assert one.ros_domain_id == 3 and one.registry == "10.0.0.2:5000"
    assert one.components == robot.components and one.discovery == robot.discovery
    two = fleet_instances(robot, fleet)["r2"]
    assert two.ros_domain_id == 7 and [h.user for h in two.hosts] == ["me", "root"]
    assert [h.ip for h in robot.hosts] == ["127.0.0.1", "127.0.0.1"]  # the project's robot is unchanged


def test_waves_place_each_robot_once_in_order(robot: Robot) -> None:
    fleet = fleet_of(10, """\
    - {name: canary, robots: [r3]}
    - {name: half, percent: 50}
    - {name: site-b, labels: {site: b}}
""", robot, labels={9: "b", 2: "b"})
    waves = plan_waves(fleet)
    assert [(w.index, w.name, w.robots) for w in waves] == [
        (0, "canary", ("r3",)),
        (1, "half", ("r1", "r2", "r4", "r5", "r6")),  # 50 % of the 9 left, rounded up
        (2, "site-b", ("r9",)),  # r2 is already placed
        (3, "rest", ("r7", "r8", "r10")),  # the implicit last wave
    ]
    assert sorted(name for w in waves for name in w.robots) == sorted(fleet.robot_names)


def test_waves_without_selector_or_robots_left(robot: Robot) -> None:
    assert [(w.name, w.robots) for w in plan_waves(fleet_of(3, "    []\n", robot))] == [("rest", ("r1", "r2", "r3"))]
    everyone = fleet_of(3, "    - {name: one, robots: [r2]}\n    - {name: all}\n", robot)
    assert [(w.name, w.robots) for w in plan_waves(everyone)] == [("one", ("r2",)), ("all", ("r1", "r3"))]
    empty = fleet_of(2, "    - {name: nobody, labels: {site: z}}\n    - {name: p, percent: 1}\n", robot)
    assert [(w.index, w.name, w.robots) for w in plan_waves(empty)] == [(0, "p", ("r1",)), (1, "rest", ("r2",))]


def test_golden_waves_of_a_twelve_robot_fleet(robot: Robot) -> None:
    fleet = fleet_of(12, """\
    - {name: canary, robots: [r1]}
    - {name: lab, labels: {site: lab}}
    - {name: quarter, percent: 25}
    - {name: half, percent: 50}
""", robot, labels={4: "lab", 11: "lab"})
    text = "".join(f"{w.index} {w.name}: {' '.join(w.robots)}\n" for w in plan_waves(fleet))
    check_golden("fleet/waves-12.txt", text)


SWARM_REFUSED = """\
ros_distro: jazzy
hosts:
  - {name: main, ip: 192.168.1.10}
components:
  - name: ok
    folder: components/ok
    runs_on: main
  - name: serial
    folder: components/serial
    runs_on: main
    devices: [/dev/ttyUSB0]
  - name: root
    folder: components/root
    runs_on: main
    privileged: true
    nvidia: true
  - name: web
    folder: components/web
    runs_on: main
    ports: ["8080:80"]
"""


def test_swarm_refuses_what_services_cannot_do_naming_robot_yaml_lines(tmp_path: Path) -> None:
    robot = parse_robot_text(SWARM_REFUSED)
    assert [path for path, _ in swarm_refusals(robot)] == [
        ("components", 1, "devices"), ("components", 2, "privileged"), ("components", 2, "nvidia"),
        ("components", 3, "ports")]
    (tmp_path / "robot.yaml").write_text(SWARM_REFUSED)
    fleet = parse_fleet_text("manager: {ip: 10.0.0.2}\nregistry: r.lan:5000\nrobots:\n"
                             "  - {name: a, hosts: {main: {ip: 10.0.0.5}}}\n", robot)
    lines = [str(p) for p in swarm_problems(robot, fleet, tmp_path / "robot.yaml")]
    assert [line.split(": ", 2)[:2] for line in lines] == [
        [f"{tmp_path}/robot.yaml:11", "components[1].devices"],
        [f"{tmp_path}/robot.yaml:15", "components[2].privileged"],
        [f"{tmp_path}/robot.yaml:16", "components[2].nvidia"],
        [f"{tmp_path}/robot.yaml:20", "components[3].ports"]]
    assert "needs devices, which Docker Swarm services cannot have" in lines[0]
    export = fleet.model_copy(update={"engine": "kubernetes"})
    assert swarm_problems(robot, export, tmp_path / "robot.yaml") == []


def test_negative_control_a_plain_robot_has_no_swarm_refusals(robot: Robot) -> None:
    assert swarm_refusals(robot) == []
