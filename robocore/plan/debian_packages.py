"""What the debian base can resolve of a package.xml: no rosdep there, so dependencies are Debian packages (pure).

rosdep's database cannot be reached from the debian base, so nothing turns a package.xml's
dependency into a Debian package by itself. A dependency resolves when the base has it (the ROS
packages its apt list installs under ``/usr/share``), when a package of the project provides it
(the workspace, ``common_packages``), or when the component's ``apt_packages`` name one of the
Debian packages that usually carry it (``ros-<name>``, ``lib<name>-dev``, ``python3-<name>``, or the
name itself, with ``-`` for ``_``). Anything else is a warning naming the package.xml line.
"""

from __future__ import annotations

import re
from collections.abc import Collection, Iterable

from robocore.plan.cmake_packages import Manifest, Refusal

#: The ROS packages of the debian base (``/usr/share/<name>/package.xml`` after its apt install).
DEBIAN_ROS_PACKAGES = frozenset({
    "actionlib_msgs", "catkin", "class_loader", "cmake_modules", "cpp_common", "diagnostic_msgs", "gencpp",
    "genlisp", "genmsg", "genpy", "geometry_msgs", "message_filters", "message_generation", "message_runtime",
    "nav_msgs", "pluginlib", "ros_environment", "rosbag", "rosbag_storage", "rosbash", "rosclean", "rosconsole",
    "rosconsole_bridge", "roscpp", "roscpp_core", "roscpp_serialization", "roscpp_traits", "roscreate",
    "rosgraph", "rosgraph_msgs", "roslaunch", "roslib", "roslz4", "rosmaster", "rosmsg", "rosnode", "rosout",
    "rospack", "rosparam", "rospy", "rosservice", "rostime", "rostopic", "roswtf", "sensor_msgs",
    "shape_msgs", "std_msgs", "std_srvs", "stereo_msgs", "topic_tools", "trajectory_msgs",
    "visualization_msgs", "xmlrpcpp",
    # system dependencies the base has (rosdep keys of the template and of common packages)
    "gtest", "python3", "python3-pytest", "python3-nose", "boost", "cmake", "git",
})


def debian_candidates(dependency: str) -> tuple[str, ...]:
    """The Debian packages that usually carry ROS package or rosdep key ``dependency``."""
    dashed = dependency.replace("_", "-").lower()
    return (f"ros-{dashed}", f"lib{dashed}-dev", f"python3-{dashed}", dashed)


#: The variables package.xml conditions test, as they are on the debian base.
CONDITION_VARIABLES = {"ROS_VERSION": "1", "ROS_PYTHON_VERSION": "3", "ROS_DISTRO": "noetic"}
_COMPARISON = re.compile(r"^\s*\$(\w+)\s*(==|!=)\s*(\S+)\s*$")


def applies(condition: str) -> bool:
    """Whether a package.xml ``condition`` (``$ROS_PYTHON_VERSION == 3``, joined by ``and``/``or``) holds on
    the debian base; a condition of another form is taken to hold."""
    if not condition.strip():
        return True
    try:
        return any(all(_holds(term) for term in part.split(" and ")) for part in condition.split(" or "))
    except ValueError:
        return True


def _holds(term: str) -> bool:
    match = _COMPARISON.match(term)
    if match is None or match[1] not in CONDITION_VARIABLES:
        raise ValueError(term)
    equal = CONDITION_VARIABLES[match[1]] == match[3].strip("'\"")
    return equal if match[2] == "==" else not equal


def unresolved(manifests: Iterable[Manifest], *, provided: Collection[str], apt: Collection[str]) -> list[Refusal]:
    """The dependencies of ``manifests`` that neither the debian base, ``provided`` (the project's own
    packages) nor a candidate Debian package in ``apt`` (the component's apt_packages) resolves."""
    names = {a.split("=", 1)[0].split("/", 1)[0] for a in apt}
    found = []
    for manifest in manifests:
        for tag, dependency, line, condition in manifest.depends:
            if not applies(condition):
                continue
            candidates = debian_candidates(dependency)
            if dependency in DEBIAN_ROS_PACKAGES or dependency in provided or names & set(candidates):
                continue
            found.append(Refusal(manifest.path, line, tag,
                                    f"{manifest.name or '?'} depends on {dependency}, which the debian base does not "
                                    "have and rosdep cannot install there: add its Debian package to the component's "
                                    f"apt_packages (e.g. {', '.join(candidates[:3])})"))
    return found
