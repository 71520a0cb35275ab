"""Discovery provisioning: how the nodes of a robot find each other, behind one interface.

robot.yaml's ``discovery.kind`` names the kind; :func:`for_robot` returns its :class:`Discovery`
for a robot. The interface and its data types are in :mod:`robocore.plan.discovery.base`; each
kind is one module here, registered in :data:`KINDS`:

* ``fastdds`` (:mod:`robocore.plan.discovery.fastdds`): Fast DDS discovery servers (ROS 2);
* ``rosmaster`` (:mod:`robocore.plan.discovery.rosmaster`): the ROS master (ROS 1).
"""

from __future__ import annotations

from collections.abc import Callable

from robocore.config.model import Robot
from robocore.errors import ConfigError, Problem
from robocore.plan.discovery.base import (
    IN_CONTAINERS,
    UDP,
    Discovery,
    FileLocator,
    Readiness,
    ReadinessCheck,
    ServerEndpoint,
    ServerProcess,
    ServerState,
    Transport,
    in_folder,
    no_files,
)
from robocore.plan.discovery.fastdds import FastDds
from robocore.plan.discovery.rosmaster import RosMaster

__all__ = [
    "IN_CONTAINERS",
    "KINDS",
    "UDP",
    "Discovery",
    "FileLocator",
    "Readiness",
    "ReadinessCheck",
    "ServerEndpoint",
    "ServerProcess",
    "ServerState",
    "Transport",
    "for_robot",
    "in_folder",
    "no_files",
]

#: robot.yaml's ``discovery.kind`` -> the implementation (a :class:`Discovery` subclass, or any factory).
KINDS: dict[str, Callable[[Robot, Transport | None], Discovery]] = {
    FastDds.kind: FastDds,
    RosMaster.kind: RosMaster,
}


def for_robot(robot: Robot, transport: Transport | None = None) -> Discovery:
    """The discovery of ``robot`` (its ``discovery.kind``, else its distro's), with the robot's transport unless
    ``transport`` is given.

    ConfigError naming ``discovery.kind`` when no implementation is registered under that kind.
    """
    kind = robot.discovery_kind
    factory = KINDS.get(kind)
    if factory is None:
        known = ", ".join(sorted(KINDS))
        raise ConfigError([Problem("robot.yaml", None, "discovery.kind",
                                   f"unknown discovery kind {kind!r} (known: {known})")])
    return factory(robot, transport)
