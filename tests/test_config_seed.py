"""Every robot.yaml example of ``config_examples`` validates unchanged once its folders exist."""

from __future__ import annotations

import pytest
from config_examples import SEED_EXAMPLES, Example
from conftest import MakeProject

from robocore.config.loader import load_robot
from robocore.config.model import DockerAccess, RosDistro
from robocore.errors import ConfigError


@pytest.mark.parametrize("example", SEED_EXAMPLES, ids=[e.name for e in SEED_EXAMPLES])
def test_seed_example_validates(make_project: MakeProject, example: Example) -> None:
    robot = load_robot(make_project(example.text, example.folders))
    assert robot.ros_distro is RosDistro.humble
    assert robot.ros_domain_id == 0
    assert robot.registry == "docker.io/dragomirxyz"
    assert robot.image_prefix == "lekiwiv2-arm64-"
    for comp in robot.components:
        assert robot.host(comp.runs_on).name == comp.runs_on


@pytest.mark.parametrize("example", [e for e in SEED_EXAMPLES if e.folders], ids=lambda e: e.name)
def test_seed_example_without_its_folders_names_each_missing_folder(
    make_project: MakeProject, example: Example
) -> None:
    with pytest.raises(ConfigError) as caught:
        load_robot(make_project(example.text))
    messages = [p.message for p in caught.value.problems]
    assert len(messages) == len(example.folders)
    for folder in example.folders:
        assert any(f"folder {folder!r} does not exist" in m for m in messages), messages


def test_full_seed_example_reads_every_field(make_project: MakeProject) -> None:
    example = SEED_EXAMPLES[0]
    robot = load_robot(make_project(example.text, example.folders))
    host = robot.host("rpi5")
    assert (host.ip, host.user, host.arch.value) == ("pi5.local", "user", "arm64")
    assert host.access is DockerAccess.ssh and not host.is_local
    pkg = robot.common_packages[0]
    assert (pkg.name, pkg.folder, pkg.repo, pkg.branch) == (
        "my_msgs",
        "common_packages/my_msgs",
        "https://github.com/you/my_msgs.git",
        "main",
    )
    agent = robot.component("micro_ros_agent")
    assert agent.folder == "components/micro_ros_agent"
    assert agent.apt_packages == []
    assert [(r.url, r.version, r.folder) for r in agent.repositories] == [
        ("https://github.com/micro-ROS/micro_ros_setup", "humble", "micro_ros_agent")
    ]
    assert agent.postinstall == [
        "ros2 run micro_ros_setup create_agent_ws.sh",
        "ros2 run micro_ros_setup build_agent.sh",
    ]
    assert agent.entrypoint == "ros2 run micro_ros_agent micro_ros_agent serial"
    assert agent.launch_args == "--dev /dev/ttyUSB0 -v6"
    assert agent.devices == ["/dev/ttyUSB0:/dev/ttyUSB0"]
    assert agent.network_mode == "host"
    assert [s.host for s in robot.discovery_servers] == ["rpi5"]


def test_vnc_example_on_devmachine(make_project: MakeProject) -> None:
    example = next(e for e in SEED_EXAMPLES if e.name == "vnc_on_devmachine")
    robot = load_robot(make_project(example.text, example.folders))
    dev = robot.host("devmachine")
    assert dev.is_local and dev.is_loopback and dev.access is DockerAccess.local
    vnc = robot.component("vnc")
    assert vnc.image == "ghcr.io/tiryoh/ros2-desktop-vnc:humble"
    assert vnc.nvidia and vnc.ports == ["6080:80"]
    assert vnc.network_mode == "bridge"
    assert [c.name for c in robot.components_on("rpi5")] == ["camera"]
    assert [c.name for c in robot.components_on("devmachine")] == ["vnc"]
    # the default discovery server is on the first host, the robot, which every host can reach
    assert [s.host for s in robot.discovery_servers] == ["rpi5"]


def test_jetson_example_maps_components_to_hosts(make_project: MakeProject) -> None:
    example = next(e for e in SEED_EXAMPLES if e.name == "jetsons")
    robot = load_robot(make_project(example.text, example.folders))
    assert {h.name: h.arch.value for h in robot.hosts} == {
        "main_computer": "amd64",
        "jetson_front": "arm64",
        "jetson_side": "arm64",
        "jetson_rear": "arm64",
    }
    assert {c.name: c.runs_on for c in robot.components} == {
        "front_inference": "jetson_front",
        "side_inference": "jetson_side",
        "rear_inference": "jetson_rear",
        "perception_aggregator": "main_computer",
    }


def test_moving_a_component_is_one_line(make_project: MakeProject) -> None:
    """The moveit example: changing runs_on moves the component; a wrong name is reported."""
    text = SEED_EXAMPLES[3].text
    assert load_robot(make_project(text)).component("moveit_planner").runs_on == "devmachine"
    with pytest.raises(ConfigError) as caught:
        load_robot(make_project(text.replace("runs_on: devmachine", "runs_on: raspberrypi5"), name="moved"))
    (problem,) = caught.value.problems
    assert problem.path == "components[0].runs_on"
    assert problem.message == "unknown host 'raspberrypi5' (known: rpi5, devmachine)"
