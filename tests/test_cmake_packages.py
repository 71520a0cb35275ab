"""CMake packages on the wheels base: detection, the one-line refusals, the image lines and the build setup."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from robocore.commands import build, prepare_base, stage
from robocore.commands.support.workspace import check_wheels_packages, wheels_cmake_packages
from robocore.errors import BuildError, ConfigError
from robocore.plan import cmake_packages, colcon, dockerfiles
from robocore.plan.cmake_packages import read_manifest, wheels_refusals
from robocore.project import Project

GOLDEN = Path(__file__).parent / "golden"

INTERFACES = """\
<?xml version="1.0"?>
<package format="3">
  <name>my_msgs</name>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <buildtool_depend>rosidl_default_generators</buildtool_depend>
  <exec_depend>rosidl_default_runtime</exec_depend>
  <member_of_group>rosidl_interface_packages</member_of_group>
  <export>
    <build_type>ament_cmake</build_type>
  </export>
</package>
"""
PYTHON = """\
<?xml version="1.0"?>
<package format="3">
  <name>{name}</name>
  <!-- rclcpp is not a dependency of this package -->
  <exec_depend>rclpy</exec_depend>
  <exec_depend>my_msgs</exec_depend>
  <export><build_type>ament_python</build_type></export>
</package>
"""
CPP_NODE = """\
<?xml version="1.0"?>
<package format="3">
  <name>cpp_node</name>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <depend>std_msgs</depend>
  <depend>rclcpp</depend>
  <export><build_type>ament_cmake</build_type></export>
</package>
"""
CPP_REFUSAL = "no rclcpp wheels: C++ nodes cannot be built on the wheels base; use base kind official"


# ------------------------------------------------------------------------------------------- package.xml


def test_build_types() -> None:
    read = read_manifest(INTERFACES, "p.xml", has_cmakelists=True)
    assert (read.path, read.name, read.build_type, read.cpp_client) == ("p.xml", "my_msgs", "ament_cmake", None)
    assert read_manifest(PYTHON.format(name="a"), "p.xml", has_cmakelists=False).build_type == "ament_python"
    assert read_manifest(INTERFACES, "p.xml", has_cmakelists=True).uses_cmake
    assert not read_manifest(PYTHON.format(name="a"), "p.xml", has_cmakelists=False).uses_cmake
    bare = INTERFACES.replace("<build_type>ament_cmake</build_type>", "")
    # no <build_type>: the ament_cmake buildtool with a CMakeLists.txt is ament_cmake, anything else
    # colcon's default (catkin)
    assert read_manifest(bare, "p.xml", has_cmakelists=True).build_type == "ament_cmake"
    assert read_manifest(bare, "p.xml", has_cmakelists=False).build_type == "catkin"
    plain_cmake = INTERFACES.replace(">ament_cmake</build_type>", ">cmake</build_type>")
    assert read_manifest(plain_cmake, "p.xml", has_cmakelists=True).uses_cmake
    assert read_manifest("<package><name>x", "p.xml", has_cmakelists=True).build_type == "unknown"


def test_a_cpp_client_dependency_is_found_with_its_tag_and_line() -> None:
    assert read_manifest(CPP_NODE, "p.xml", has_cmakelists=True).cpp_client == ("depend", "rclcpp", 6)
    action = PYTHON.format(name="a").replace("<exec_depend>my_msgs</exec_depend>",
                                             "<test_depend>rclcpp_action</test_depend>")
    assert read_manifest(action, "p.xml", has_cmakelists=False).cpp_client == ("test_depend", "rclcpp_action", 6)
    # negative controls: a comment naming rclcpp, rclpy, and a doc dependency are not C++ client dependencies
    assert read_manifest(PYTHON.format(name="a"), "p.xml", has_cmakelists=False).cpp_client is None
    doc = PYTHON.format(name="a").replace("<exec_depend>my_msgs</exec_depend>", "<doc_depend>rclcpp</doc_depend>")
    assert read_manifest(doc, "p.xml", has_cmakelists=False).cpp_client is None


def test_a_package_name_never_reaches_the_dockerfile_as_anything_but_a_name() -> None:
    evil = INTERFACES.replace("<name>my_msgs</name>", "<name>x\nRUN touch /pwned</name>")
    manifest = read_manifest(evil, "p.xml", has_cmakelists=True)
    assert cmake_packages.cmake_packages([manifest]) == ["?"]
    lines = cmake_packages.toolchain_lines("jazzy", "/v", ["x\nRUN touch /pwned", "ok_name"])
    assert lines[0].startswith("# CMake packages (?, ok_name)") and "pwned" not in "\n".join(lines)


def test_rclcpp_is_refused_on_the_wheels_base_in_one_line() -> None:
    node = read_manifest(CPP_NODE, "components/a/src/cpp_node/package.xml", has_cmakelists=True)
    msgs = read_manifest(INTERFACES, "components/a/src/my_msgs/package.xml", has_cmakelists=True)
    assert wheels_refusals("jazzy", [msgs]) == []
    [refusal] = wheels_refusals("jazzy", [msgs, node])
    assert (refusal.file, refusal.line, refusal.key, refusal.message) == (
        "components/a/src/cpp_node/package.xml", 6, "depend", CPP_REFUSAL)


def test_cmake_packages_on_a_distro_without_pinned_tools_are_refused() -> None:
    msgs = read_manifest(INTERFACES, "ws/my_msgs/package.xml", has_cmakelists=True)
    python = read_manifest(PYTHON.format(name="a"), "ws/a/package.xml", has_cmakelists=False)
    assert wheels_refusals("kilted", [python, msgs]) == []
    assert wheels_refusals("rolling", [python]) == []
    [refusal] = wheels_refusals("rolling", [python, msgs])
    assert refusal.file == "ws/my_msgs/package.xml" and "for jazzy, kilted only, not rolling" in refusal.message


# ------------------------------------------------------------------------------------------- pins


def test_the_tool_sets_pin_every_wheel_cmake_needs() -> None:
    pins = cmake_packages.CMAKE_WHEELS["jazzy"]
    names = [pin.split("==")[0] for pin in pins]
    assert len(names) == len(set(names))
    assert all(re.fullmatch(r"ros-[a-z0-9-]+==[0-9][0-9.]*", pin) for pin in pins)
    wanted = {f"ros-{name}" for name in (
        "ament-cmake", "ament-cmake-ros", "ament-cmake-gmock", "ament-cmake-gtest", "ament-cmake-pytest",
        "ament-package", "ament-index-python", "ament-lint", "rosidl-default-generators",
        "rosidl-typesupport-fastrtps-c", "rosidl-generator-py", "fastcdr", "fastrtps", "fastrtps-cmake-module",
        "python-cmake-module", "rcutils", "rcpputils", "rpyutils", "builtin-interfaces", "service-msgs", "action-msgs",
        "unique-identifier-msgs", "type-description-interfaces", "gmock-vendor", "gtest-vendor")}
    assert wanted <= set(names)
    # the Jazzy releases of the base's wheels: ament_cmake 2.5, rosidl 4.6, Fast DDS 2.14
    assert "ros-ament-cmake==2.5.4" in pins and "ros-rosidl-parser==4.6.6" in pins and "ros-fastrtps==2.14.5" in pins
    assert "ros-rclpy==7.1.6" in dockerfiles.WHEELS["jazzy"]
    kilted = cmake_packages.CMAKE_WHEELS["kilted"]
    assert {"ros-ament-cmake==2.7.3", "ros-rosidl-parser==4.9.5", "ros-fastdds==3.2.3"} <= set(kilted)
    assert "ros-rclpy==9.1.2" in dockerfiles.WHEELS["kilted"]
    assert set(cmake_packages.CMAKE_WHEELS) == set(dockerfiles.WHEELS)


# ------------------------------------------------------------------------------------------- Dockerfiles


def _robot(**extra: object) -> object:
    from robocore.config.model import Robot

    data = {"ros_distro": "jazzy", "base": {"kind": "wheels"}, "hosts": [{"name": "dev", "ip": "127.0.0.1"}],
            "components": [{"name": "a", "runs_on": "dev", "folder": "components/a"}], **extra}
    return Robot.model_validate(data)


def test_a_component_with_cmake_packages_gets_the_tool_chain_before_its_repositories() -> None:
    from robocore.config.model import Robot

    robot = _robot()
    assert isinstance(robot, Robot)
    comp = robot.component("a")
    text = dockerfiles.component_dockerfile(robot, comp, base_ref="b", repo_folders=["tools"], cmake=["my_msgs"])
    lines = text.splitlines()
    label = lines.index("LABEL dev.robocore.toolchain=cmake")
    assert label < lines.index("COPY repos /tmp/robocore/deps")
    assert "apt-get install -y --no-install-recommends cmake g++ gcc make python3-dev ccache" in text
    assert f"/opt/ros/jazzy/venv/bin/pip install {' '.join(cmake_packages.CMAKE_WHEELS['jazzy'])}" in text
    assert "ln -sfn /usr/include/python$v /opt/python/$t/include/python$v" in text
    assert "ln -sfn /opt/ros/jazzy/venv/lib/python$v /opt/python/$t/lib/python$v" in text
    # negative control: without CMake packages, nothing of it
    plain = dockerfiles.component_dockerfile(robot, comp, base_ref="b")
    assert "toolchain" not in plain and "cmake" not in plain
    # the official base has its own tool chain
    official = Robot.model_validate({**robot.model_dump(mode="json", exclude_none=True), "base": {"kind": "official"}})
    assert "toolchain" not in dockerfiles.component_dockerfile(official, official.component("a"), base_ref="b",
                                                               cmake=["my_msgs"])


def test_a_common_cmake_package_puts_the_tool_chain_into_the_base_golden() -> None:
    import os

    from robocore.config.model import Robot

    robot = _robot(common_packages=[{"name": "my_msgs"}])
    assert isinstance(robot, Robot)
    text = dockerfiles.base_dockerfile(robot, root_image="robocore/debian:bookworm", has_ca=False,
                                       common=["my_msgs"], cmake=["my_msgs"])
    lines = text.splitlines()
    assert lines.index("LABEL dev.robocore.toolchain=cmake") < lines.index("COPY common /tmp/robocore/common")
    path = GOLDEN / "base-wheels-cmake-common.Dockerfile"
    if os.environ.get("UPDATE_GOLDEN"):
        path.write_text(text)
    assert text == path.read_text(), "differs from its golden file (UPDATE_GOLDEN=1 to accept)"
    # the same base without a CMake package is the unchanged base
    assert "toolchain" not in dockerfiles.base_dockerfile(robot, root_image="r", has_ca=False, common=["my_msgs"])


# ------------------------------------------------------------------------------------------- stage and validate


def _write(root: Path, files: dict[str, str]) -> None:
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)


ROBOT_YAML = """\
ros_distro: {distro}
base: {{kind: wheels}}
hosts: [{{name: dev, ip: 127.0.0.1}}]
common_packages: [{{name: shared_msgs, folder: shared/shared_msgs}}]
components:
  - {{name: msgs, folder: components/msgs, runs_on: dev}}
  - {{name: py, folder: components/py, runs_on: dev}}
"""


def _project(tmp_path: Path, distro: str = "jazzy", extra: dict[str, str] | None = None) -> Project:
    _write(tmp_path, {
        "robot.yaml": ROBOT_YAML.format(distro=distro),
        "components/msgs/src/my_msgs/package.xml": INTERFACES,
        "components/msgs/src/my_msgs/CMakeLists.txt": "project(my_msgs)\n",
        "components/msgs/src/user/package.xml": PYTHON.format(name="user"),
        "components/py/src/user/package.xml": PYTHON.format(name="user"),
        "shared/shared_msgs/package.xml": INTERFACES.replace("my_msgs", "shared_msgs"),
        "shared/shared_msgs/CMakeLists.txt": "project(shared_msgs)\n",
        **(extra or {}),
    })
    return Project.load(tmp_path)


def test_stage_plans_the_tool_chain_only_where_a_workspace_needs_it(tmp_path: Path) -> None:
    project = _project(tmp_path)
    base = stage.BaseRef(ref="p-base:latest", arch="amd64", inputs="x")
    msgs = stage.plan_component(project, project.component("msgs"), base, dry_run=True)
    py = stage.plan_component(project, project.component("py"), base, dry_run=True)
    assert "# CMake packages (my_msgs)" in msgs.plan.dockerfile
    assert "toolchain" not in py.plan.dockerfile
    planned = prepare_base.plan_base(project, None, "amd64", dry_run=True)
    assert "# CMake packages (shared_msgs)" in planned.plan.dockerfile


def test_stage_and_validate_refuse_rclcpp_in_one_line_naming_the_file(tmp_path: Path) -> None:
    project = _project(tmp_path, extra={"components/py/src/cpp_node/package.xml": CPP_NODE,
                                        "components/py/src/cpp_node/CMakeLists.txt": "project(cpp_node)\n"})
    base = stage.BaseRef(ref="p-base:latest", arch="amd64", inputs="x")
    with pytest.raises(ConfigError) as raised:
        stage.plan_component(project, project.component("py"), base, dry_run=True)
    assert raised.value.lines() == [f"components/py/src/cpp_node/package.xml:6: depend: {CPP_REFUSAL}"]
    with pytest.raises(ConfigError) as validated:
        check_wheels_packages(project)
    assert validated.value.lines() == raised.value.lines()
    stage.plan_component(project, project.component("msgs"), base, dry_run=True)  # the other one is fine


def test_the_refusal_is_one_line_on_the_command_line(tmp_path: Path) -> None:
    import subprocess
    import sys

    _project(tmp_path, extra={"components/py/src/cpp_node/package.xml": CPP_NODE,
                              "components/py/src/cpp_node/CMakeLists.txt": "project(cpp_node)\n"})
    done = subprocess.run([sys.executable, "-m", "robocore", "-p", str(tmp_path), "validate"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().splitlines() == [
        f"error: components/py/src/cpp_node/package.xml:6: depend: {CPP_REFUSAL}"]


def test_other_bases_are_not_asked(tmp_path: Path) -> None:
    project = _project(tmp_path, extra={"components/py/src/cpp_node/package.xml": CPP_NODE})
    official = tmp_path / "robot.yaml"
    official.write_text(official.read_text().replace("kind: wheels", "kind: official"))
    project = Project.load(tmp_path)
    check_wheels_packages(project)  # rclcpp is fine on the official base
    assert wheels_cmake_packages(project, [tmp_path / "components/msgs"]) == []


# ------------------------------------------------------------------------------------------- build


def test_build_runs_jobs_on_every_core_and_ccache_where_the_image_has_it(tmp_path: Path) -> None:
    argv = colcon.workspace_build_argv(["a"], 2)
    assert argv[argv.index("--parallel-workers") + 1] == "2" and argv[argv.index("--packages-above") + 1] == "a"
    assert "--parallel-workers" not in colcon.workspace_build_argv()
    env = colcon.build_env(2)
    assert env["CMAKE_BUILD_PARALLEL_LEVEL"] == "2" and env["MAKEFLAGS"] == "-j2" and "CCACHE_DIR" not in env
    cached = colcon.build_env(4, ccache=True)
    assert cached["CCACHE_DIR"] == colcon.CONTAINER_CCACHE and cached["CCACHE_DEPEND"] == "1"
    assert cached["CMAKE_C_COMPILER_LAUNCHER"] == cached["CMAKE_CXX_COMPILER_LAUNCHER"] == "ccache"
    mounts = colcon.workspace_mounts(tmp_path / "ws", tmp_path / "out", tmp_path / "cc")
    assert mounts[str(tmp_path / "cc")] == colcon.CONTAINER_CCACHE

    project = _project(tmp_path)
    plan = build.plan_build(project, project.component("msgs"), "img")
    assert plan.workers >= 1 and plan.argv[plan.argv.index("--parallel-workers") + 1] == str(plan.workers)
    with_cache = build.with_cmake_toolchain(project, plan, {cmake_packages.LABEL_TOOLCHAIN: "cmake"})
    assert with_cache.ccache == project.state_dir / "ccache" / plan.arch  # one cache per arch
    with pytest.raises(BuildError, match=r"my_msgs build with CMake, but its image was staged without"):
        build.with_cmake_toolchain(project, plan, {})
    python_only = build.plan_build(project, project.component("py"), "img")
    assert build.with_cmake_toolchain(project, python_only, {}).ccache is None


def test_an_interface_or_header_edit_always_runs_colcon() -> None:
    from robocore.plan.install_patch import plan_patches, verbatim_copies

    before = {"pkg": {"msg/Greeting.msg": ("m1", False), "include/pkg/a.hpp": ("h1", False)}}
    sources = {**before["pkg"], "msg/Greeting.msg": ("m2", False)}
    outputs = {"install/pkg/share/pkg/msg/Greeting.msg": "m1", "install/pkg/include/pkg/a.hpp": "h1"}
    # installed as they are, yet never recorded as plain copies
    assert verbatim_copies("pkg", before["pkg"], outputs) == {}
    copies = {"pkg": {"msg/Greeting.msg": ["install/pkg/share/pkg/msg/Greeting.msg"]}}  # as an older state had it
    patches, why = plan_patches(["pkg"], before, {"pkg": sources}, copies)
    assert patches == [] and why == "pkg: code is generated or compiled from msg/Greeting.msg"
    header = {**before["pkg"], "include/pkg/a.hpp": ("h2", False)}
    copies = {"pkg": {"include/pkg/a.hpp": ["install/pkg/include/pkg/a.hpp"]}}
    assert plan_patches(["pkg"], before, {"pkg": header}, copies) == (
        [], "pkg: code is generated or compiled from include/pkg/a.hpp")


def test_the_wheels_base_context_holds_robocores_files_at_their_image_paths(tmp_path: Path) -> None:
    """The one ``COPY tree/ /`` of the wheels base puts the entrypoint, setup.bash and ros2 where the image
    uses them (executables stay executable)."""
    planned = prepare_base.plan_base(_project(tmp_path), None, "amd64", dry_run=True)
    files = {f.dest: f for f in planned.files}
    assert {"tree/robocore/entrypoint.sh", "tree/opt/ros/jazzy/setup.bash", "tree/opt/ros/jazzy/venv/bin/ros2"} <= set(
        files)
    assert files["tree/robocore/entrypoint.sh"].executable and files["tree/opt/ros/jazzy/venv/bin/ros2"].executable
    assert b"@DISTRO@" not in files["tree/opt/ros/jazzy/setup.bash"].data
    assert not [d for d in files if not d.startswith(("tree/", "common/"))]
