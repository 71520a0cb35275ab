"""Cross-checks of fleet.yaml against itself and against the project's robot.yaml.

They run on :class:`FleetParts`, the robots and waves that validated (all of them for a valid file),
so one run reports a field error and a duplicate name together. Each check yields
``(key path, message)``; the loader adds file and line.

The rules: every robot gives an address for every host of robot.yaml and for no other host; robot
names are unique; no address (of any host of any robot) is used twice, and none is a loopback address
(a fleet's nodes are reached from the manager); wave names are unique, a wave's ``robots`` name robots
of the fleet, each robot named by one wave at most; a wave without a selector takes every robot left,
so it is the last one (and ``rest``, the name of the implicit last wave, takes no selector); a maintenance
window's ``robots`` name robots of the fleet; the swarm
engine needs its manager; a fleet runs images from a registry, its own or robot.yaml's; the manager, and each
robot's hosts as merged with robot.yaml's, pass robot.yaml's host checks (how each daemon is reached).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from robocore.config.hints import Unknown, known_list
from robocore.config.host_addresses import address_key
from robocore.config.model import is_loopback_address
from robocore.config.registry_ca import registry_ca_problems

if TYPE_CHECKING:
    from pathlib import Path

    from robocore.config.fleet import FleetRobot, Manager, Wave, Window
    from robocore.config.model import Robot

KeyPath = tuple[str | int, ...]
Found = tuple[KeyPath, str]

#: The implicit last wave's name (kept equal to :data:`robocore.config.fleet.REST_WAVE`; a test checks it).
REST = "rest"


@dataclass(frozen=True)
class FleetParts:
    """The validated parts of one fleet.yaml, each with its index in the file."""

    robots: list[tuple[int, FleetRobot]] = field(default_factory=list)
    waves: list[tuple[int, Wave]] = field(default_factory=list)
    #: ``engine`` as written (None when it is not text).
    engine: str | None = "swarm"
    has_manager: bool = False
    registry: str | None = None
    manager: Manager | None = None
    #: ``registry_ca`` as written (None when not set or not text).
    registry_ca: str | None = None
    windows: list[tuple[int, Window]] = field(default_factory=list)


def check_fleet(parts: FleetParts, robot: Robot, project: Path | None = None) -> list[Found]:
    """Every cross-field problem of the fleet ``parts`` with the project's ``robot``; ``project`` (its folder) adds
    the checks that look at files."""
    return [*_unique_robots(parts), *_hosts(parts, robot), *_addresses(parts), *_waves(parts), *_engine(parts, robot),
            *_docker_access(parts, robot, project),
            *registry_ca_problems(parts.registry_ca, project.resolve() if project else None,
                                  has_registry=parts.registry is not None or robot.registry is not None),
            *_windows(parts)]


def _windows(parts: FleetParts) -> Iterator[Found]:
    """A maintenance window's ``robots`` name robots of the fleet."""
    names = Unknown("robot", [fleet_robot.name for _, fleet_robot in parts.robots])
    for index, window in parts.windows:
        for position, name in enumerate(window.robots or []):
            if name not in names:
                yield ("rollout", "windows", index, "robots", position), names.message(name)


def _docker_access(parts: FleetParts, robot: Robot, project: Path | None) -> Iterator[Found]:
    """The manager, and each robot's hosts as merged with robot.yaml's, through robot.yaml's host checks: a daemon
    reached by plain TCP without ``insecure``, ``tls`` without files, TLS files outside the project, ports and flags
    that do not apply."""
    from robocore.config.checks import host_problems, tls_file_problems

    if parts.manager is not None:
        manager = [(0, parts.manager.as_host())]
        found = [*host_problems(manager), *(tls_file_problems(manager, project.resolve()) if project else [])]
        for key, message in found:
            yield ("manager", *key[2:]), message.replace("on this host", "on the manager")
    hosts = {host.name: host for host in robot.hosts}
    for index, fleet_robot in parts.robots:
        for name, given in fleet_robot.hosts.items():
            if name not in hosts or (given.docker is None and given.docker_port is None):
                continue  # an unknown host is said by _hosts; robot.yaml's own settings are checked there
            for key, message in host_problems([(0, given.on(hosts[name]))]):
                yield (("robots", index, "hosts", name, *key[2:]),
                       f"{message} (robot.yaml's host {name} as robot {fleet_robot.name} has it)")


def _unique_robots(parts: FleetParts) -> Iterator[Found]:
    first: dict[str, int] = {}
    for index, fleet_robot in parts.robots:
        if fleet_robot.name in first:
            yield ("robots", index, "name"), (f"duplicate robot name {fleet_robot.name!r} "
                                              f"(also robots[{first[fleet_robot.name]}])")
        else:
            first[fleet_robot.name] = index


def _hosts(parts: FleetParts, robot: Robot) -> Iterator[Found]:
    names = [host.name for host in robot.hosts]
    hosts = Unknown("host", names)
    for index, fleet_robot in parts.robots:
        for name in fleet_robot.hosts:
            if name not in hosts:
                yield ("robots", index, "hosts", name), hosts.message(name)
        missing = [name for name in names if name not in fleet_robot.hosts]
        if missing:
            yield (("robots", index, "hosts"),
                   f"robot {fleet_robot.name!r} gives no address for host(s) {known_list(missing)} of robot.yaml; "
                   "every robot gives one for each host")


def _addresses(parts: FleetParts) -> Iterator[Found]:
    seen: dict[str, str] = {}
    for index, fleet_robot in parts.robots:
        for name, host in fleet_robot.hosts.items():
            where: KeyPath = ("robots", index, "hosts", name, "ip")
            key = address_key(host.ip)
            if is_loopback_address(key):
                yield where, (f"{host.ip!r} is a loopback address; a fleet's hosts are reached from the manager and "
                              "from each other, so each needs its network address")
                continue
            if key in seen:
                yield where, f"address {host.ip!r} is also {seen[key]}; each host of each robot is one machine"
            else:
                seen[key] = f"robots[{index}].hosts.{name} (robot {fleet_robot.name!r})"


def _waves(parts: FleetParts) -> Iterator[Found]:
    names = Unknown("robot", [fleet_robot.name for _, fleet_robot in parts.robots])
    first_wave: dict[str, int] = {}
    named_by: dict[str, str] = {}
    open_ended: str | None = None
    for index, wave in parts.waves:
        where: KeyPath = ("rollout", "waves", index)
        if wave.name in first_wave:
            yield (*where, "name"), f"duplicate wave name {wave.name!r} (also rollout.waves[{first_wave[wave.name]}])"
        else:
            first_wave[wave.name] = index
        if wave.name == REST and not wave.selects_rest:
            yield (*where, "name"), (f"{REST!r} is the wave of every robot not yet placed and takes no selector; "
                                     "give this wave another name")
        if open_ended is not None:
            yield (*where, "name"), (f"wave {wave.name!r} comes after wave {open_ended!r}, which takes every robot "
                                     "left (it has no selector); it would always be empty")
        if wave.selects_rest and open_ended is None:
            open_ended = wave.name
        for position, name in enumerate(wave.robots or []):
            if name not in names:
                yield (*where, "robots", position), names.message(name)
            elif name in named_by:
                yield (*where, "robots", position), f"robot {name!r} is already named by {named_by[name]}"
            else:
                named_by[name] = f"wave {wave.name!r} (rollout.waves[{index}])"


def _engine(parts: FleetParts, robot: Robot) -> Iterator[Found]:
    if parts.engine == "swarm" and not parts.has_manager:
        yield ("manager",), "the swarm engine needs its manager (manager: {ip: ..., user: ...})"
    if parts.registry is None and robot.registry is None:
        yield ("registry",), ("a fleet runs release images from a registry: set registry here or in robot.yaml "
                              "(e.g. registry: 10.0.0.2:5000)")
