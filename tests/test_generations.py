"""ROS generations (ROS 1 and ROS 2): what robot.yaml may combine, the debian base's Dockerfile and setup.bash,
and golden base Dockerfiles of ROS 1 robots (set UPDATE_GOLDEN=1 to rewrite the goldens)."""

from __future__ import annotations

import subprocess
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from golden_files import check_golden

from robocore import resources
from robocore.commands.support import images
from robocore.config.generations import generation_problems
from robocore.config.loader import parse_robot_text
from robocore.config.model import Robot
from robocore.errors import ConfigError
from robocore.plan import arches, cmake_packages, dockerfiles

BASE = """\
ros_distro: noetic
base:
  kind: official
hosts:
  - name: pi
    ip: 192.168.1.20
  - name: dev
    ip: 192.168.1.10
components:
  - name: talker
    folder: components/talker
    runs_on: pi
  - name: listener
    folder: components/listener
    runs_on: dev
"""

DESKTOP_APT = "[tigervnc-standalone-server, tigervnc-tools, novnc, websockify]"


def edit(replace: dict[int, str] | None = None, *, after: dict[int, str] | None = None) -> str:
    """BASE with line N replaced (``replace``) or text inserted after line N (``after``); numbers refer to BASE."""
    out: list[str] = []
    for number, line in enumerate(BASE.splitlines(), start=1):
        out.append((replace or {}).get(number, line))
        if after and number in after:
            out.append(after[number].rstrip("\n"))
    return "\n".join(out) + "\n"


def distro_and_base(distro: str, kind: str) -> str:
    return edit({1: f"ros_distro: {distro}", 3: f"  kind: {kind}"})


def refusal(text: str) -> list[str]:
    with pytest.raises(ConfigError) as caught:
        parse_robot_text(text)
    return caught.value.lines()


# ------------------------------------------------------------------ bases


def test_the_debian_base_refuses_a_ros2_distro() -> None:
    assert refusal(distro_and_base("jazzy", "debian")) == [
        "robot.yaml:3: base.kind: the debian base has Debian 12's ROS 1 packages (noetic generation) only, "
        "not ROS 2 jazzy; use base.kind: wheels or official"]


def test_the_debian_base_refuses_melodic_and_points_to_official() -> None:
    assert refusal(distro_and_base("melodic", "debian")) == [
        "robot.yaml:3: base.kind: the debian base has Debian 12's ROS 1 packages (noetic generation) only, "
        "not ROS 1 melodic; use base.kind: official"]


@pytest.mark.parametrize("distro", ["noetic", "melodic"])
def test_the_wheels_base_refuses_ros1(distro: str) -> None:
    assert refusal(distro_and_base(distro, "wheels")) == [
        f"robot.yaml:3: base.kind: the wheels base has ROS 2 only (PyPI wheels), not ROS 1 {distro}; "
        "use base.kind: debian (noetic) or official"]


@pytest.mark.parametrize(("distro", "kind"), [
    ("noetic", "debian"), ("noetic", "official"), ("melodic", "official"), ("jazzy", "wheels"),
    ("humble", "official")])
def test_each_generation_loads_with_its_bases(distro: str, kind: str) -> None:
    r = parse_robot_text(distro_and_base(distro, kind))
    assert r.ros_distro.value == distro and r.base.kind.value == kind
    assert r.ros_version == (1 if distro in ("noetic", "melodic") else 2)
    assert r.generation == f"ROS {r.ros_version}"
    assert r.discovery_kind == ("rosmaster" if r.ros_version == 1 else "fastdds")
    assert list(generation_problems(r)) == []


# ------------------------------------------------------------------ discovery kinds


def test_fast_dds_on_a_ros1_robot_is_refused() -> None:
    assert refusal(edit(after={3: "discovery:\n  kind: fastdds"})) == [
        "robot.yaml:5: discovery.kind: fastdds is ROS 2 discovery, but ros_distro noetic is ROS 1: a robot runs "
        "one ROS generation (no ros1_bridge); use kind: rosmaster"]


def test_the_ros_master_on_a_ros2_robot_is_refused() -> None:
    text = edit({1: "ros_distro: jazzy"}, after={3: "discovery:\n  kind: rosmaster"})
    assert refusal(text) == [
        "robot.yaml:5: discovery.kind: rosmaster is ROS 1 discovery, but ros_distro jazzy is ROS 2: a robot runs "
        "one ROS generation (no ros1_bridge); use kind: fastdds"]


def test_each_generation_accepts_its_own_kind_by_name() -> None:
    assert parse_robot_text(edit(after={3: "discovery:\n  kind: rosmaster"})).discovery_kind == "rosmaster"
    jazzy = edit({1: "ros_distro: jazzy"}, after={3: "discovery:\n  kind: fastdds"})
    assert parse_robot_text(jazzy).discovery_kind == "fastdds"


def test_a_ros1_robot_has_one_master() -> None:
    text = edit(after={3: "discovery:\n  servers:\n    - host: pi\n    - host: dev"})
    assert refusal(text) == ["robot.yaml:7: discovery.servers[1]: a ROS 1 robot has one ROS master: list one server"]


def test_one_master_with_its_own_port_loads() -> None:
    r = parse_robot_text(edit(after={3: "discovery:\n  servers:\n    - host: dev\n      port: 12000"}))
    assert [(s.host, s.port) for s in r.discovery_servers] == [("dev", 12000)]


def test_two_fast_dds_servers_stay_fine_on_ros2() -> None:
    """Control: the one-master rule is ROS 1's."""
    text = edit({1: "ros_distro: jazzy"}, after={3: "discovery:\n  servers:\n    - host: pi\n    - host: dev"})
    assert [(s.host, s.port) for s in parse_robot_text(text).discovery_servers] == [("pi", 11811), ("dev", 11811)]


# ------------------------------------------------------------------ networks

BRIDGE_ON_DEV = "    network: bridge"


def test_a_bridge_component_on_a_two_host_ros1_robot_is_refused() -> None:
    assert refusal(edit(after={15: BRIDGE_ON_DEV})) == [
        "robot.yaml:16: components[1].network: listener: ROS 1 nodes listen on random ports that nodes on the "
        "robot's other hosts must reach, which a bridge network hides; use network: host (ports are then not needed)"]


def test_published_ports_mean_a_bridge_network_and_are_refused_too() -> None:
    lines = refusal(edit(after={15: "    ports: ['8080:80']"}))
    assert len(lines) == 1 and lines[0].startswith("robot.yaml:13: components[1].network: listener: ROS 1 nodes")


def test_a_bridge_component_on_a_one_host_ros1_robot_loads() -> None:
    text = edit({12: "    runs_on: dev"}, after={3: "discovery:\n  servers:\n    - host: dev", 15: BRIDGE_ON_DEV})
    r = parse_robot_text(text)
    assert [h.name for h in r.hosts_in_use()] == ["dev"]
    # the master is a host in use too: on the (otherwise idle) first host it makes two hosts, and a refusal
    assert refusal(edit({12: "    runs_on: dev"}, after={15: BRIDGE_ON_DEV}))[0].startswith(
        "robot.yaml:16: components[1].network: listener:")
    assert r.component("listener").network_mode == "bridge"


def test_a_bridge_component_on_a_two_host_ros2_robot_loads() -> None:
    """Control: Fast DDS reaches bridge containers through its discovery server."""
    r = parse_robot_text(edit({1: "ros_distro: jazzy"}, after={15: BRIDGE_ON_DEV}))
    assert r.component("listener").network_mode == "bridge"


def test_a_desktop_component_on_a_bridge_network_is_exempt() -> None:
    desktop = (f"  - name: vnc\n    runs_on: dev\n    network: bridge\n    desktop: {{}}\n"
               f"    apt_packages: {DESKTOP_APT}")
    r = parse_robot_text(edit(after={15: desktop}))
    assert r.component("vnc").network_mode == "bridge" and r.component("vnc").desktop is not None


def test_every_generation_problem_is_reported_at_once() -> None:
    text = edit({3: "  kind: wheels"}, after={3: "discovery:\n  kind: fastdds", 15: BRIDGE_ON_DEV})
    assert [line.split(": ")[0:2] for line in refusal(text)] == [
        ["robot.yaml:3", "base.kind"], ["robot.yaml:5", "discovery.kind"], ["robot.yaml:18", "components[1].network"]]


# ------------------------------------------------------------------ the debian base Dockerfile


def robot(**overrides: Any) -> Robot:
    data: dict[str, Any] = {
        "ros_distro": "noetic",
        "base": {"kind": "debian"},
        "hosts": [{"name": "dev", "ip": "127.0.0.1"}, {"name": "pi", "ip": "10.0.0.2", "arch": "arm64"}],
        "components": [
            {
                "name": "driver",
                "runs_on": "dev",
                "folder": "components/driver",
                "apt_packages": ["libusb-1.0-0", "ros-std-msgs-dev"],
                "repositories": [{"url": "https://github.com/example/serial_tools.git", "version": "v1.2.0"}],
            },
        ],
    }
    data.update(overrides)
    return Robot.model_validate(data)


def debian_base(common: list[str] | None = None) -> str:
    return dockerfiles.base_dockerfile(robot(), root_image="robocore/debian:bookworm", has_ca=False,
                                       common=common or [])


def run_line(text: str, needle: str) -> str:
    """The RUN instruction holding ``needle``, its continuation lines joined."""
    (line,) = [line for line in text.replace("\\\n", "").splitlines() if line.startswith("RUN ") and needle in line]
    return line


def test_the_debian_base_installs_debians_ros1_packages() -> None:
    line = run_line(debian_base(), "apt-get install")
    installed = line.split("--no-install-recommends ", 1)[1].split(" && ", 1)[0].split()
    assert installed == list(dockerfiles.DEBIAN_APT)
    assert "ros-core-dev" in installed and "ccache" in installed
    assert not any(name.startswith("ros-noetic-") for name in installed)  # Debian's names, not the ROS repository's


def test_the_debian_base_has_colcon_in_a_venv_that_sees_debians_ros() -> None:
    text = debian_base()
    line = run_line(text, "python3 -m venv")
    # no pip of its own: Debian's pip, seen through the system site packages, installs into the venv it runs in
    assert "python3 -m venv --without-pip --system-site-packages /opt/ros/noetic/venv" in line
    assert f"/opt/ros/noetic/venv/bin/python -m pip install {' '.join(dockerfiles.DEBIAN_TOOLS)}" in line
    assert "python3-pip" in dockerfiles.DEBIAN_APT
    assert "ln -sf /opt/ros/noetic/venv/bin/colcon /usr/local/bin/colcon" in line
    assert "colcon-ros" in dockerfiles.DEBIAN_TOOLS and "colcon-cmake" in dockerfiles.DEBIAN_TOOLS


def test_the_debian_base_makes_ninja_build_trees() -> None:
    text = debian_base()
    assert "ninja-build" in dockerfiles.DEBIAN_APT and "ninja-build" in run_line(text, "dpkg -s")
    assert "    CMAKE_GENERATOR=Ninja" in text.splitlines() or "ENV CMAKE_GENERATOR=Ninja" in text.splitlines()
    wheels = dockerfiles.base_dockerfile(robot(ros_distro="jazzy", base={"kind": "wheels"}),
                                         root_image="robocore/debian:bookworm", has_ca=False, common=[])
    assert "CMAKE_GENERATOR" not in wheels  # control: the other bases keep CMake's default generator


def test_the_debian_base_is_labelled_with_the_tool_chain_in_the_builds_one_label_step() -> None:
    """The label rides in the plan's labels, which the build writes in its one final LABEL step (a step of its
    own costs seconds), and which the inputs hash covers."""
    toolchain = {cmake_packages.LABEL_TOOLCHAIN: cmake_packages.TOOLCHAIN_CMAKE}
    assert dockerfiles.base_labels(robot()) == toolchain
    assert "LABEL" not in debian_base()
    assert dockerfiles.base_labels(robot(ros_distro="jazzy", base={"kind": "wheels"})) == {}  # control
    plan = dockerfiles.ImagePlan(role="base", name="p-base", tag="latest", arch="amd64", dockerfile=debian_base(),
                                 parent="robocore/debian:bookworm", labels=toolchain)
    labelled = images.planned(SimpleNamespace(name="p"), plan, "sha256:root")  # type: ignore[arg-type]
    assert labelled.labels[cmake_packages.LABEL_TOOLCHAIN] == cmake_packages.TOOLCHAIN_CMAKE
    assert labelled.labels["dev.robocore.project"] == "p"
    bare = images.planned(SimpleNamespace(name="p"), replace(plan, labels={}), "sha256:root")  # type: ignore[arg-type]
    assert cmake_packages.LABEL_TOOLCHAIN not in bare.labels and bare.inputs != labelled.inputs


def test_the_debian_base_sets_the_distro_and_its_setup_file() -> None:
    text = debian_base()
    assert text.startswith("# robocore base image, ROS 1 noetic (debian): ")
    assert "FROM robocore/debian:bookworm" in text.splitlines()
    assert "ENV ROS_DISTRO=noetic \\" in text.splitlines()
    assert "COPY tree/ /" in text.splitlines()  # debian-setup.bash as /opt/ros/noetic/setup.bash, the entrypoint
    assert dockerfiles.base_tree_dest("debian-setup.bash", "noetic") == "tree/opt/ros/noetic/setup.bash"
    assert text.rstrip().endswith("&& ln -sfn noetic /opt/ros/Debian")  # setup.bash sets ROS_DISTRO=Debian
    assert 'ENTRYPOINT ["/robocore/entrypoint.sh"]' in text.splitlines() and 'CMD ["bash"]' in text.splitlines()
    # one build step per instruction, each a commit of the ~800 MB root: few (labels go in the build's last LABEL)
    steps = [line for line in text.splitlines() if line and not line.startswith(("#", " ", "FROM"))]
    assert len(steps) == 6, steps
    assert "wheels-setup.bash" not in text and "WHEELS-UNAVAILABLE" not in text


def test_the_debian_base_runs_no_rosdep() -> None:
    text = debian_base()
    assert "rosdep" not in text
    official = dockerfiles.base_dockerfile(robot(base={"kind": "official"}), root_image="ros:noetic-ros-base",
                                           has_ca=False, common=[])
    assert 'rosdep update --rosdistro "$ROS_DISTRO"' in official  # control: the official base has rosdep


def test_the_debian_base_runs_no_rosdep_for_common_packages() -> None:
    text = debian_base(["my_msgs"])
    assert "COPY common /tmp/robocore/common" in text  # they are built...
    assert "rosdep" not in text  # ...without rosdep, which the debian base does not have


def test_a_debian_component_runs_no_rosdep_even_with_package_xmls() -> None:
    r = robot()
    comp = r.component("driver")
    text = dockerfiles.component_dockerfile(r, comp, base_ref="proj-base:latest",
                                            package_xmls=["rosdep/src/driver/package.xml"],
                                            repo_folders=[dockerfiles.repo_folder(comp.repositories[0])])
    assert "rosdep" not in text
    assert "libusb-1.0-0 ros-std-msgs-dev" in text  # dependencies are Debian package names in apt_packages
    assert "COPY repos /tmp/robocore/deps" in text and "colcon" in text
    official = robot(base={"kind": "official"})
    control = dockerfiles.component_dockerfile(official, official.component("driver"), base_ref="b",
                                               package_xmls=["rosdep/src/driver/package.xml"])
    assert "rosdep install" in control


@pytest.mark.parametrize("distro", ["noetic", "melodic"])
def test_the_official_base_of_a_ros1_distro_gets_colcon_from_apt(distro: str) -> None:
    r = robot(ros_distro=distro, base={"kind": "official"})
    assert arches.upstream_root(r) == f"ros:{distro}-ros-base"
    text = dockerfiles.base_dockerfile(r, root_image=arches.upstream_root(r), has_ca=False, common=[])
    line = run_line(text, "apt-get install")
    assert line.split("--no-install-recommends ", 1)[1].split(" && ", 1)[0].split() == list(
        dockerfiles.OFFICIAL_ROS1_APT)
    assert "python3-colcon-common-extensions" in line
    assert text.startswith(f"# robocore base image, ROS 1 {distro} (official): ")
    jazzy = robot(ros_distro="jazzy", base={"kind": "official"})
    ros2 = dockerfiles.base_dockerfile(jazzy, root_image="ros:jazzy-ros-base", has_ca=False, common=[])
    assert "python3-colcon-common-extensions" not in ros2  # control: ROS 2 images have colcon


# ------------------------------------------------------------------ golden base Dockerfiles


def test_debian_noetic_base_golden() -> None:
    text = dockerfiles.base_dockerfile(robot(), root_image="robocore/debian:bookworm", has_ca=True, common=[])
    check_golden("base-debian-noetic.Dockerfile", text)


def test_debian_noetic_base_with_common_packages_golden() -> None:
    text = dockerfiles.base_dockerfile(robot(), root_image="robocore/debian:bookworm", has_ca=False,
                                       common=["my_msgs", "utils"])
    check_golden("base-debian-noetic-common.Dockerfile", text)


def test_official_noetic_base_golden() -> None:
    r = robot(base={"kind": "official"})
    text = dockerfiles.base_dockerfile(r, root_image=arches.upstream_root(r), has_ca=True, common=["my_msgs"])
    check_golden("base-official-noetic.Dockerfile", text)


def test_official_melodic_base_golden() -> None:
    r = robot(ros_distro="melodic", base={"kind": "official"})
    text = dockerfiles.base_dockerfile(r, root_image=arches.upstream_root(r), has_ca=False, common=[])
    check_golden("base-official-melodic.Dockerfile", text)


# ------------------------------------------------------------------ debian-setup.bash


def source_setup(tmp_path: Path, env: dict[str, str] | None = None) -> dict[str, str]:
    """debian-setup.bash sourced by bash in an environment of only ``env`` (and PATH): the exported variables."""
    setup = tmp_path / "setup.bash"
    setup.write_bytes(resources.read("debian-setup.bash"))
    done = subprocess.run(["bash", "--noprofile", "--norc", "-c", f"set -u; source {setup}; exec env"],
                          env={"PATH": "/usr/bin:/bin", **(env or {})}, capture_output=True, text=True, check=True)
    return dict(line.split("=", 1) for line in done.stdout.splitlines() if "=" in line)


def test_debian_setup_gives_a_clean_shell_the_ros1_variables(tmp_path: Path) -> None:
    env = source_setup(tmp_path)
    assert env["ROS_VERSION"] == "1"
    assert env["ROS_PYTHON_VERSION"] == "3"
    assert env["ROS_PACKAGE_PATH"] == "/usr/share"
    assert env["CMAKE_PREFIX_PATH"] == "/usr"
    assert env["ROS_ROOT"] == "/usr/share/ros" and env["ROS_ETC_DIR"] == "/etc/ros"
    # Debian's own name for its distro (its catkin hook insists); the image links /opt/ros/Debian to noetic
    assert env["ROS_DISTRO"] == "Debian"


def test_debian_setup_keeps_what_the_environment_already_says_first(tmp_path: Path) -> None:
    env = source_setup(tmp_path, {"ROS_PACKAGE_PATH": "/ws/src", "CMAKE_PREFIX_PATH": "/opt/robocore/common",
                                  "ROS_ROOT": "/elsewhere/ros"})
    assert env["ROS_PACKAGE_PATH"] == "/ws/src:/usr/share"  # Debian's packages stay findable, after
    assert env["CMAKE_PREFIX_PATH"] == "/opt/robocore/common:/usr"
    assert env["ROS_ROOT"] == "/elsewhere/ros"
    assert env["ROS_VERSION"] == "1"  # the generation is this image's whatever the caller said


def test_debian_setup_can_be_sourced_twice(tmp_path: Path) -> None:
    setup = tmp_path / "setup.bash"
    setup.write_bytes(resources.read("debian-setup.bash"))
    done = subprocess.run(["bash", "--noprofile", "--norc", "-c",
                           f"set -eu; source {setup}; source {setup}; echo \"$ROS_PACKAGE_PATH|$CMAKE_PREFIX_PATH\""],
                          env={"PATH": "/usr/bin:/bin"}, capture_output=True, text=True, check=True)
    assert done.stdout == "/usr/share|/usr\n"


def test_a_debian_components_pip_packages_use_a_pip_the_base_has() -> None:
    r = robot(components=[{"name": "driver", "runs_on": "dev", "folder": "c", "pip_packages": ["pyserial>=3.5"]}])
    base = debian_base()
    pip = run_line(dockerfiles.component_dockerfile(r, r.component("driver"), base_ref="b"), "pip install")
    system_pip = ("python3-pip" in dockerfiles.DEBIAN_APT and "PIP_BREAK_SYSTEM_PACKAGES=1" in base
                  and pip.startswith("RUN python3 -m pip"))
    venv_pip = "/opt/ros/noetic/venv/bin/" in pip or "PATH=/opt/ros/noetic/venv/bin" in base
    assert system_pip or venv_pip
