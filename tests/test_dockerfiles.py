"""Golden-file tests of the generated Dockerfiles (set UPDATE_GOLDEN=1 to rewrite the goldens)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from golden_files import check_golden

from robocore.config.model import Robot
from robocore.plan import arches, dockerfiles


def robot(**overrides: Any) -> Robot:
    data: dict[str, Any] = {
        "ros_distro": "jazzy",
        "hosts": [{"name": "dev", "ip": "127.0.0.1"}, {"name": "pi", "ip": "10.0.0.2", "arch": "arm64"}],
        "components": [
            {
                "name": "driver",
                "runs_on": "dev",
                "folder": "components/driver",
                "apt_packages": ["libusb-1.0-0", "ros-jazzy-diagnostic-updater"],
                "pip_packages": ["pyserial>=3.5", "numpy"],
                "repositories": [{"url": "https://github.com/example/serial_tools.git", "version": "v1.2.0"}],
                "postinstall": ["echo 'done' > /etc/driver-ready", "ros2 pkg list | grep -q rclpy"],
            },
            {"name": "plain", "runs_on": "dev", "folder": "components/plain"},
        ],
    }
    data.update(overrides)
    return Robot.model_validate(data)


def test_wheels_base_golden() -> None:
    r = robot(base={"kind": "wheels"})
    text = dockerfiles.base_dockerfile(r, root_image="robocore/debian:bookworm", has_ca=True, common=[])
    check_golden("base-wheels.Dockerfile", text)


def test_wheels_base_with_common_packages_golden() -> None:
    r = robot(base={"kind": "wheels"}, ros_distro="kilted")
    text = dockerfiles.base_dockerfile(r, root_image="debian:bookworm", has_ca=False, common=["my_msgs", "utils"])
    check_golden("base-wheels-kilted-common.Dockerfile", text)


def test_official_base_golden() -> None:
    r = robot()
    text = dockerfiles.base_dockerfile(r, root_image=arches.upstream_root(r), has_ca=True, common=["my_msgs"])
    check_golden("base-official.Dockerfile", text)


def test_component_official_golden() -> None:
    r = robot()
    comp = r.component("driver")
    text = dockerfiles.component_dockerfile(
        r, comp, base_ref="proj-base:latest",
        package_xmls=["rosdep/src/driver/package.xml"],
        repo_folders=[dockerfiles.repo_folder(comp.repositories[0])],
    )
    check_golden("component-official.Dockerfile", text)


def test_rosdep_stops_the_build_on_a_key_it_cannot_resolve() -> None:
    """Without ``-r`` (continue despite errors), a key rosdep cannot resolve fails the image's build: with it,
    rosdep reports the key, exits 0, and the image silently lacks the dependency (seen on the official stand-ins)."""
    r = robot()
    texts = [dockerfiles.component_dockerfile(r, r.component("driver"), base_ref="proj-base:latest",
                                              package_xmls=["rosdep/src/driver/package.xml"]),
             dockerfiles.base_dockerfile(r, root_image="ros:jazzy-ros-base", has_ca=False, common=["msgs"])]
    for text in texts:
        [line] = [line for line in text.splitlines() if "rosdep install" in line]
        assert " -y " in line and " -r " not in line, line


def test_rosdep_unresolved_names_each_package_and_key() -> None:
    output = [
        "Step 3/5 : RUN apt-get update && rosdep install ...",
        "ERROR: the following packages/stacks could not have their rosdep keys resolved",
        "to system dependencies:",
        "demo_x: Cannot locate rosdep definition for [robocore_no_such_key]",
        "demo_y: No definition of [libfoo] for OS version [bookworm]",
        "demo_x: Cannot locate rosdep definition for [robocore_no_such_key]",
    ]
    assert dockerfiles.rosdep_unresolved(output) == [
        "package demo_x: no rosdep definition of 'robocore_no_such_key'",
        "package demo_y: no rosdep definition of 'libfoo' for OS version [bookworm]",
    ]
    assert dockerfiles.rosdep_unresolved(["#All required rosdeps installed successfully"]) == []


def test_rosdep_unresolved_reads_a_line_the_builder_coloured() -> None:
    # Docker's classic builder starts a chunk of a step's stderr with a colour sequence
    coloured = "\x1b[91mdemo_talker: Cannot locate rosdep definition for [robocore_no_such_key]\x1b[0m"
    assert dockerfiles.rosdep_unresolved([coloured]) == [
        "package demo_talker: no rosdep definition of 'robocore_no_such_key'"]


def test_component_wheels_golden() -> None:
    r = robot(base={"kind": "wheels"})
    comp = r.component("driver")
    text = dockerfiles.component_dockerfile(r, comp, base_ref="proj-base:latest",
                                            repo_folders=[dockerfiles.repo_folder(comp.repositories[0])])
    check_golden("component-wheels.Dockerfile", text)


def test_component_without_dependencies_is_just_the_base() -> None:
    r = robot()
    text = dockerfiles.component_dockerfile(r, r.component("plain"), base_ref="proj-base:latest")
    assert [line for line in text.splitlines() if not line.startswith("#")] == ["FROM proj-base:latest"]


def test_wheels_base_has_entrypoint_setup_and_pins() -> None:
    r = robot(base={"kind": "wheels"})
    text = dockerfiles.base_dockerfile(r, root_image="x", has_ca=False, common=[])
    assert 'ENTRYPOINT ["/robocore/entrypoint.sh"]' in text
    assert 'CMD ["bash"]' in text
    assert f"COPY {dockerfiles.BASE_TREE}/ /" in text  # robocore's files, each at its path in the image
    assert dockerfiles.base_tree_dest("wheels-setup.bash", "jazzy") == "tree/opt/ros/jazzy/setup.bash"
    assert dockerfiles.base_tree_dest("ros2", "jazzy") == "tree/opt/ros/jazzy/venv/bin/ros2"
    assert dockerfiles.base_tree_dest("entrypoint.sh", "jazzy") == "tree/robocore/entrypoint.sh"
    for pin in dockerfiles.WHEELS["jazzy"]:
        assert pin in text
    assert "host-ca.pem" not in text  # no trust store found -> nothing copied


def test_the_wheels_base_commits_nothing_after_its_venv_but_the_label() -> None:
    """A build step's commit costs in proportion to the image on fuse-overlayfs: the files, settings, entrypoint
    and command all come before the venv's RUN (one COPY, one ENV), so a plain wheels base ends with it."""
    r = robot(base={"kind": "wheels"})
    text = dockerfiles.base_dockerfile(r, root_image="x", has_ca=True, common=[])
    steps = [line.split()[0] for line in text.splitlines() if line and not line.startswith((" ", "#"))]
    assert steps == ["FROM", "SHELL", "COPY", "ENV", "ENTRYPOINT", "CMD", "RUN"]
    assert "PIP_CERT=/etc/robocore/host-ca.pem" in text and "PATH=/opt/ros/jazzy/venv/bin:$PATH" in text


def test_official_base_uses_override() -> None:
    r = robot(base={"kind": "official", "image": "myreg/ros:jazzy-custom"})
    assert arches.upstream_root(r) == "myreg/ros:jazzy-custom"
    assert arches.upstream_root(robot()) == "ros:jazzy-ros-base"


def test_pip_requirements_are_shell_quoted() -> None:
    r = robot()
    text = dockerfiles.component_dockerfile(r, r.component("driver"), base_ref="b")
    assert "'pyserial>=3.5'" in text


@pytest.mark.parametrize("distro", ["humble", "rolling"])
def test_wheels_refuses_distros_without_wheels(distro: str) -> None:
    r = robot(base={"kind": "wheels"}, ros_distro=distro, components=[])
    problems = dockerfiles.wheels_problems(r)
    assert problems and problems[0][0] == ("ros_distro",) and "official" in problems[0][1]


def test_wheels_refuses_arm64_hosts_with_components() -> None:
    comps = [{"name": "cam", "runs_on": "pi", "folder": "c"}]
    problems = dockerfiles.wheels_problems(robot(base={"kind": "wheels"}, components=comps))
    assert problems == [(("hosts", 1, "arch"), problems[0][1])]
    assert "amd64" in problems[0][1]
    # an arm64 host without components to build is fine; the official base is always fine
    assert dockerfiles.wheels_problems(robot(base={"kind": "wheels"}, components=[])) == []
    assert dockerfiles.wheels_problems(robot(components=comps)) == []


def test_wheels_refuses_a_fast_dds_server_on_an_arm64_host() -> None:
    """The server runs the base of its host's arch, which the wheels base cannot make for arm64."""
    on_pi = robot(base={"kind": "wheels"}, components=[], discovery={"servers": [{"host": "pi"}]})
    [(path, message)] = dockerfiles.wheels_problems(on_pi)
    assert path == ("hosts", 1, "arch") and "a Fast DDS discovery server" in message and "master" not in message
    assert dockerfiles.wheels_problems(robot(base={"kind": "wheels"}, components=[],
                                             discovery={"servers": [{"host": "dev"}]})) == []


def test_repo_folder_from_url() -> None:
    from robocore.config.model import Repository

    assert dockerfiles.repo_folder(Repository(url="https://x.org/a/b_c.git")) == "b_c"
    assert dockerfiles.repo_folder(Repository(url="git@x.org:a/tools")) == "tools"
    assert dockerfiles.repo_folder(Repository(url="https://x.org/a/b.git", folder="mine")) == "mine"


def test_base_tag_per_arch() -> None:
    assert arches.base_tag("amd64", "amd64") == "latest"
    assert arches.base_tag("arm64", "amd64") == "latest-arm64"


def _shim(args: list[str], prefixes: list[Path]) -> Any:
    import subprocess
    import sys

    from robocore import resources

    env = {"AMENT_PREFIX_PATH": ":".join(str(p) for p in prefixes), "PATH": "/usr/bin:/bin"}
    code = resources.read("ros2").decode()
    return subprocess.run([sys.executable, "-c", code, *args], env=env, capture_output=True, text=True)


def test_ros2_shim_runs_executables_and_lists_packages(tmp_path: Path) -> None:
    first, second = tmp_path / "install" / "pkg_a", tmp_path / "venv"
    for prefix, pkg in ((first, "pkg_a"), (second, "rclpy")):
        (prefix / "share/ament_index/resource_index/packages").mkdir(parents=True)
        (prefix / "share/ament_index/resource_index/packages" / pkg).write_text("")
    exe = first / "lib/pkg_a/hello"
    exe.parent.mkdir(parents=True)
    exe.write_text("#!/bin/sh\necho \"hello $*\"\n")
    exe.chmod(0o755)
    done = _shim(["run", "pkg_a", "hello", "--ros-args", "-p", "x:=1"], [first, second])
    assert done.returncode == 0 and done.stdout.strip() == "hello --ros-args -p x:=1", done.stderr
    assert _shim(["pkg", "list"], [first, second]).stdout.split() == ["pkg_a", "rclpy"]
    assert _shim(["pkg", "prefix", "rclpy"], [first, second]).stdout.strip() == str(second)
    assert _shim(["pkg", "executables", "pkg_a"], [first, second]).stdout.strip() == "pkg_a hello"
    missing = _shim(["run", "pkg_a", "nope"], [first, second])
    assert missing.returncode == 1 and "No executable found" in missing.stderr
    assert "Package 'zzz' not found" in _shim(["run", "zzz", "x"], [first]).stderr
