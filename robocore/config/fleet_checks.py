"""Cross-checks of fleet.yaml against itself and against the project's robot.yaml.

They run on :class:`FleetParts`, the robots and waves that validated (all of them for a valid file),
so one run reports a field error and a duplicate name together. Each check yields
``(key path, message)``; the loader adds file and line.

The rules: every robot gives an address for every host of robot.yaml and for no other host; robot
names are unique; no address (of any host of any robot) is used twice, and none is a loopback address
(a fleet's nodes are reached from the manager); wave names are unique, a wave's ``robots`` name robots
of the fleet, each robot named by one wave at most; a wave without a selector takes every robot left,
so it is the last one (and ``rest``, the name of the implicit last wave, takes no selector); the swarm
engine needs its manager; a fleet runs images from a registry, its own or robot.yaml's.
"""

from __future__ import annotations

import ipaddress
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from robocore.config.hints import Unknown, known_list
from robocore.config.model import is_loopback_address

if TYPE_CHECKING:
    from robocore.config.fleet import FleetRobot, Wave
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


def check_fleet(parts: FleetParts, robot: Robot) -> list[Found]:
    """Every cross-field problem of the fleet ``parts`` with the project's ``robot``."""
    return [*_unique_robots(parts), *_hosts(parts, robot), *_addresses(parts), *_waves(parts), *_engine(parts, robot)]


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


def _address_key(address: str) -> str:
    """An address as compared for duplicates: IP addresses in their canonical form, host names in lower case."""
    try:
        return str(ipaddress.ip_address(address))
    except ValueError:
        return address.lower().rstrip(".")


def _addresses(parts: FleetParts) -> Iterator[Found]:
    seen: dict[str, str] = {}
    for index, fleet_robot in parts.robots:
        for name, host in fleet_robot.hosts.items():
            where: KeyPath = ("robots", index, "hosts", name, "ip")
            if is_loopback_address(host.ip):
                yield where, (f"{host.ip!r} is a loopback address; a fleet's hosts are reached from the manager and "
                              "from each other, so each needs its network address")
                continue
            key = _address_key(host.ip)
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
