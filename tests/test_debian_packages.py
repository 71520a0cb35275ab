"""The debian base has no rosdep: package.xml dependencies that nothing resolves are warnings with file and line."""

from __future__ import annotations

from pathlib import Path

import yaml

from robocore.commands.support.workspace import debian_dependency_warnings
from robocore.config.loader import load_robot
from robocore.plan.cmake_packages import read_manifest
from robocore.plan.debian_packages import applies, debian_candidates, unresolved
from robocore.project import Project

TALKER_XML = """\
<?xml version="1.0"?>
<package format="3">
  <name>demo_talker</name>
  <version>0.1.0</version>
  <description>t</description>
  <maintainer email="me@example.com">me</maintainer>
  <license>Apache-2.0</license>
  <buildtool_depend>catkin</buildtool_depend>
  <depend>roscpp</depend>
  <depend>demo_msgs</depend>
  <depend>tf2_ros</depend>
  <exec_depend>helper_pkg</exec_depend>
  <test_depend condition="$ROS_PYTHON_VERSION == 2">python-pytest</test_depend>
  <test_depend condition="$ROS_PYTHON_VERSION == 3">python3-pytest</test_depend>
  <test_depend>gtest</test_depend>
</package>
"""
HELPER_XML = TALKER_XML.replace("<name>demo_talker</name>", "<name>helper_pkg</name>").replace(
    "  <depend>tf2_ros</depend>\n", "").replace("  <exec_depend>helper_pkg</exec_depend>\n", "")


def manifest(text: str = TALKER_XML) -> object:
    return read_manifest(text, "components/talker/src/demo_talker/package.xml", has_cmakelists=True)


def test_every_dependency_is_read_with_its_tag_line_and_condition() -> None:
    depends = read_manifest(TALKER_XML, "p.xml", has_cmakelists=True).depends
    assert depends[0] == ("buildtool_depend", "catkin", 8, "")
    assert ("depend", "tf2_ros", 11, "") in depends
    assert ("test_depend", "python-pytest", 13, "$ROS_PYTHON_VERSION == 2") in depends


def test_conditions_are_evaluated_as_on_the_debian_base() -> None:
    assert applies("") and applies("$ROS_PYTHON_VERSION == 3") and applies("$ROS_VERSION == 1")
    assert not applies("$ROS_PYTHON_VERSION == 2") and not applies("$ROS_VERSION == 2")
    assert applies("$ROS_VERSION == 2 or $ROS_PYTHON_VERSION == 3")
    assert not applies("$ROS_VERSION == 1 and $ROS_PYTHON_VERSION != 3")
    assert applies("some other form")  # not understood: taken to hold, so the dependency is still checked


def test_what_nothing_resolves_is_named_with_its_file_line_and_tag() -> None:
    read = read_manifest(TALKER_XML, "components/talker/src/demo_talker/package.xml", has_cmakelists=True)
    found = unresolved([read], provided={"demo_msgs"}, apt=[])
    assert [(u.file, u.line, u.key) for u in found] == [
        ("components/talker/src/demo_talker/package.xml", 11, "depend"),
        ("components/talker/src/demo_talker/package.xml", 12, "exec_depend"),
    ]
    assert "demo_talker depends on tf2_ros" in found[0].message and "ros-tf2-ros" in found[0].message


def test_an_apt_package_among_the_candidates_resolves_it() -> None:
    read = read_manifest(TALKER_XML, "p.xml", has_cmakelists=True)
    assert debian_candidates("tf2_ros") == ("ros-tf2-ros", "libtf2-ros-dev", "python3-tf2-ros", "tf2-ros")
    found = unresolved([read], provided={"demo_msgs", "helper_pkg"}, apt=["libtf2-ros-dev=0.7.6-1"])
    assert found == []
    # control: an unrelated Debian package resolves nothing
    assert len(unresolved([read], provided={"demo_msgs", "helper_pkg"}, apt=["libyaml-cpp-dev"])) == 1


def _project(tmp_path: Path, kind: str, apt: list[str] | None = None) -> Project:
    for rel, text in {"components/talker/src/demo_talker/package.xml": TALKER_XML,
                      "components/talker/src/helper_pkg/package.xml": HELPER_XML}.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    (tmp_path / "common" / "demo_msgs").mkdir(parents=True)
    (tmp_path / "common" / "demo_msgs" / "package.xml").write_text(
        HELPER_XML.replace("<name>helper_pkg</name>", "<name>demo_msgs</name>"))
    data = {"ros_distro": "noetic", "base": {"kind": kind}, "hosts": [{"name": "dev", "ip": "127.0.0.1"}],
            "common_packages": [{"name": "demo_msgs", "folder": "common/demo_msgs"}],
            "components": [{"name": "talker", "folder": "components/talker", "runs_on": "dev",
                            "apt_packages": apt or []}]}
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    return Project(root=tmp_path, robot=load_robot(tmp_path))


def test_validate_warns_on_the_debian_base_only(tmp_path: Path) -> None:
    [warning] = debian_dependency_warnings(_project(tmp_path / "a", "debian"))
    assert warning.severity == "warning" and warning.line == 11 and warning.path == "depend"
    assert warning.file == "components/talker/src/demo_talker/package.xml" and "tf2_ros" in warning.message
    assert debian_dependency_warnings(_project(tmp_path / "b", "debian", ["python3-tf2-ros"])) == []
    assert debian_dependency_warnings(_project(tmp_path / "c", "official")) == []  # rosdep resolves it there
