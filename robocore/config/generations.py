"""What a robot's ROS generation (ROS 1 or ROS 2) allows: bases, discovery kinds, networks.

One robot.yaml names one distro, so all of a robot's hosts run one generation: a ROS 2 discovery
kind on a ROS 1 robot (or the reverse) would mean hosts of both generations, which cannot talk
without a bridge robocore does not provide. Each rule yields ``(key path, message)``; the loader
adds file and line.
"""

from __future__ import annotations

from collections.abc import Iterator

from robocore.config.model import ROS1_DISTROS, BaseKind, Robot

KeyPath = tuple[str | int, ...]
Found = tuple[KeyPath, str]

#: The distros the debian base can build (Debian 12 packages ROS 1.15, the noetic generation).
DEBIAN_DISTROS = ("noetic",)


def generation_problems(robot: Robot) -> Iterator[Found]:
    """Every combination of distro, base, discovery kind and network that cannot work."""
    yield from _bases(robot)
    yield from _discovery(robot)
    yield from _networks(robot)


def base_problem(distro: str, kind: str, *, setting: str = "base.kind: ") -> str | None:
    """Why base ``kind`` cannot serve ``distro`` (one line, naming ``setting`` as the thing to change), or None."""
    ros1 = distro in ROS1_DISTROS
    if kind == BaseKind.debian.value and distro not in DEBIAN_DISTROS:
        other = "official" if ros1 else "wheels or official"
        return (f"the debian base has Debian 12's ROS 1 packages (noetic generation) only, "
                f"not ROS {1 if ros1 else 2} {distro}; use {setting}{other}")
    if kind == BaseKind.wheels.value and ros1:
        return (f"the wheels base has ROS 2 only (PyPI wheels), not ROS 1 {distro}; "
                f"use {setting}debian (noetic) or official")
    return None


def _bases(robot: Robot) -> Iterator[Found]:
    problem = base_problem(robot.ros_distro.value, robot.base.kind.value)
    if problem is not None:
        yield ("base", "kind"), problem


def _discovery(robot: Robot) -> Iterator[Found]:
    kind = robot.discovery.kind
    if kind == "fastdds" and robot.ros_version == 1:
        yield (("discovery", "kind"), f"fastdds is ROS 2 discovery, but ros_distro {robot.ros_distro.value} is "
                                      "ROS 1: a robot runs one ROS generation (no ros1_bridge); use kind: rosmaster")
    if kind == "rosmaster" and robot.ros_version == 2:
        yield (("discovery", "kind"), f"rosmaster is ROS 1 discovery, but ros_distro {robot.ros_distro.value} is "
                                      "ROS 2: a robot runs one ROS generation (no ros1_bridge); use kind: fastdds")
    if robot.discovery_kind == "rosmaster":
        for index in range(1, len(robot.discovery.servers)):
            yield (("discovery", "servers", index), "a ROS 1 robot has one ROS master: list one server")


def _networks(robot: Robot) -> Iterator[Found]:
    """ROS 1 nodes listen on random ports that other hosts connect to: no bridge network across hosts."""
    in_use = {h.name for h in robot.hosts_in_use()}
    if robot.ros_version != 1 or len(in_use) < 2:
        return
    for index, host in enumerate(robot.hosts):
        if host.is_loopback and host.name in in_use:
            yield (("hosts", index, "ip"),
                   f"{host.name}: ROS 1 nodes tell the others their host's address, and {host.ip!r} is a loopback "
                   "address that the robot's other hosts cannot reach; give this host its LAN address")
    for index, comp in enumerate(robot.components):
        if comp.network_mode == "bridge" and comp.desktop is None:
            yield (("components", index, "network"),
                   f"{comp.name}: ROS 1 nodes listen on random ports that nodes on the robot's other hosts must "
                   "reach, which a bridge network hides; use network: host (ports are then not needed)")
