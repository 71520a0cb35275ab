"""The fleet plan (pure): each robot as a robot.yaml of its own, the waves of a rollout, and what an engine refuses.

- :func:`robot_instance` turns the project's robot.yaml and one robot of fleet.yaml into the
  :class:`~robocore.config.model.Robot` of that robot: its hosts at its addresses, users and ports,
  its ROS domain, the fleet's registry. Everything else (components, discovery, base) is robot.yaml's.
- :func:`plan_waves` orders the robots into waves: each robot goes in the first wave that selects it
  (by name, by label, or a percentage of the robots not yet placed, rounded up, in fleet-file order);
  a wave without a selector takes every robot left; robots no wave took go in a last wave ``rest``.
  Waves that select nobody are left out of the plan.
- :func:`swarm_refusals` lists what Docker Swarm services cannot do for a component of robot.yaml
  (devices, privileged, GPUs, bridge networking and published ports, robocore's X11/VNC plumbing);
  :func:`swarm_problems` gives them as ``robot.yaml:LINE: key: problem`` lines. A Swarm fleet refuses
  them at plan time, before anything changes (docs/fleets.md says why refuse rather than run them
  beside Swarm).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from robocore.config.fleet import REST_WAVE, Fleet, FleetRobot
from robocore.config.model import Component, Host, Robot
from robocore.errors import Problem

KeyPath = tuple[str | int, ...]
Found = tuple[KeyPath, str]


def instance_host(host: Host, fleet_robot: FleetRobot) -> Host:
    """robot.yaml's ``host`` as ``fleet_robot`` has it (:meth:`~robocore.config.fleet.FleetHost.on`): its address,
    and its user, ports and Docker access when the fleet file gives them."""
    return fleet_robot.hosts[host.name].on(host)


def robot_instance(robot: Robot, fleet_robot: FleetRobot, *, registry: str | None = None) -> Robot:
    """The robot.yaml model of one robot of the fleet: ``robot`` with ``fleet_robot``'s host addresses, users,
    ports and ROS domain applied, and ``registry`` (the fleet's, see :meth:`Fleet.registry_for`) when given.

    ``fleet_robot`` must give every host of ``robot`` (the fleet file's checks make sure of it).
    """
    update: dict[str, object] = {"hosts": [instance_host(host, fleet_robot) for host in robot.hosts]}
    if fleet_robot.ros_domain_id is not None:
        update["ros_domain_id"] = fleet_robot.ros_domain_id
    if registry is not None:
        update["registry"] = registry
    return robot.model_copy(update=update)


def fleet_instances(robot: Robot, fleet: Fleet) -> dict[str, Robot]:
    """Every robot of ``fleet`` as its own robot.yaml model (:func:`robot_instance`), by name, in file order."""
    registry = fleet.registry_for(robot)
    return {fleet_robot.name: robot_instance(robot, fleet_robot, registry=registry) for fleet_robot in fleet.robots}


@dataclass(frozen=True)
class WavePlan:
    """One wave of a rollout: its name, its place in the rollout (0 first) and its robots in fleet-file order."""

    index: int
    name: str
    robots: tuple[str, ...]


def plan_waves(fleet: Fleet) -> tuple[WavePlan, ...]:
    """The waves of ``fleet``'s rollout, in order, each robot in exactly one (see the module's docstring)."""
    left = list(fleet.robot_names)
    by_name = {robot.name: robot for robot in fleet.robots}
    chosen: list[tuple[str, list[str]]] = []
    for wave in fleet.rollout.waves:
        if wave.robots is not None:
            wanted = set(wave.robots)
            picked = [name for name in left if name in wanted]
        elif wave.labels is not None:
            labels = wave.labels.items()
            picked = [name for name in left if labels <= by_name[name].labels.items()]
        elif wave.percent is not None:
            picked = left[: math.ceil(len(left) * wave.percent / 100)]
        else:
            picked = list(left)
        taken = set(picked)
        left = [name for name in left if name not in taken]
        chosen.append((wave.name, picked))
    if left:
        chosen.append((REST_WAVE, left))
    waves = [(name, robots) for name, robots in chosen if robots]
    return tuple(WavePlan(index, name, tuple(robots)) for index, (name, robots) in enumerate(waves))


# --- what Swarm services cannot do ------------------------------------------------------------------------------


def _component_refusals(index: int, component: Component) -> Iterator[Found]:
    where: KeyPath = ("components", index)
    if component.devices:
        yield (*where, "devices"), (f"component {component.name!r} needs devices, which Docker Swarm services "
                                    "cannot have; a Swarm fleet refuses it (run it with robocore run on each robot)")
    if component.privileged:
        yield (*where, "privileged"), (f"component {component.name!r} is privileged, which Docker Swarm services "
                                       "cannot be; a Swarm fleet refuses it")
    if component.nvidia:
        yield (*where, "nvidia"), (f"component {component.name!r} asks for the GPU; Docker Swarm hands GPUs to "
                                   "services only as generic resources the NVIDIA runtime ignores, so a Swarm fleet "
                                   "refuses it")
    if component.network == "bridge" or (component.network is None and component.ports):
        key = "network" if component.network is not None else "ports"
        yield (*where, key), (f"component {component.name!r} runs on Docker's bridge network with published ports; "
                              "Swarm services run on the host network in a fleet (DDS needs it), so use "
                              "network: host")
    if component.gui is not False:
        yield (*where, "gui"), (f"component {component.name!r} draws windows through robocore's per-host X11 "
                                "setup, which a Swarm service does not get; a Swarm fleet refuses it")
    if component.desktop is not None:
        yield (*where, "desktop"), (f"component {component.name!r} serves a VNC desktop whose password robocore "
                                    "keeps per host; a Swarm fleet refuses it")


def swarm_refusals(robot: Robot) -> list[Found]:
    """What Docker Swarm services cannot run of ``robot`` (robot.yaml), as ``(key path, message)``, in file order.

    Swarm's service spec has no devices, privileged, ipc, shm size or GPU assignment (the Docker CLI's
    ``UnsupportedProperties``); ``ipc: host``, which robocore gives same-host containers for shared memory,
    becomes a bind mount of the host's ``/dev/shm`` instead and is not refused.
    """
    return [found for index, component in enumerate(robot.components)
            for found in _component_refusals(index, component)]


def swarm_problems(robot: Robot, fleet: Fleet, robot_file: Path) -> list[Problem]:
    """The refusals of a Swarm ``fleet`` for ``robot``, one ``robot.yaml:LINE: key: problem`` each (read from
    ``robot_file`` for the lines); none for another engine. Call before anything changes."""
    if fleet.engine != "swarm":
        return []
    found = swarm_refusals(robot)
    if not found:
        return []
    from robocore.config.loader import located

    return located(robot_file, found).problems
