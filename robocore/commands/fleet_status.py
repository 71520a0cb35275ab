"""``fleet status``: one row per robot of the fleet, read from the manager only.

Release running: the release whose images every component's current task runs (``mixed`` while they differ,
``-`` when nothing runs); target: the release its services are set to; health: the last gate's verdict; state:
``online``, ``offline`` (a node of it is not ready) and ``pending`` (it does not run its target yet); last
change: when the target last changed. All of it comes from the services' labels and tasks and the nodes' states.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from robocore.adapters import swarm
from robocore.commands.fleet_swarm import load, manager_client, offline, project_label, robot_nodes
from robocore.commands.support.context import Options
from robocore.plan import naming
from robocore.plan import swarm_services as plan

#: What an offline robot runs when the manager no longer keeps its tasks (it drops them when a node goes down).
UNKNOWN = "?"


@dataclass(frozen=True)
class FleetRobotRow:
    """One robot in ``fleet status``."""

    kind: ClassVar[str] = "fleet_robot"
    robot: str
    running: str
    target: str
    health: str
    state: str  # online | offline | pending | offline, pending
    changed: str


def _running(services: list[swarm.ServiceInfo], tasks: dict[str, list[swarm.TaskInfo]], *, offline: bool) -> str:
    """The release whose images every component service's running task runs (its target first, then the one
    before it, as an unchanged component has both), ``mixed`` when no one release has them all, ``-`` when a
    component runs nothing. On an ``offline`` robot, its last task that had a container (what the robot ran when
    it was last heard of) is taken while the manager keeps it, else the release is :data:`UNKNOWN`."""
    common: set[str] | None = None
    order: list[str] = []
    for service in services:
        if service.labels.get(naming.LABEL_ROLE) != naming.ROLE_COMPONENT:
            continue
        live = [t for t in tasks.get(service.name, []) if t.state == "running" or (offline and t.container)]
        if not live:
            return UNKNOWN if offline else "-"
        image = live[0].image
        target, previous = service.labels.get(plan.LABEL_RELEASE, ""), service.labels.get(plan.LABEL_PREVIOUS, "")
        matches = set()
        if image == service.image and target:
            matches.add(target)
        if image and image == service.labels.get(plan.LABEL_PREVIOUS_IMAGE) and previous:
            matches.add(previous)
        order += [target, previous]
        common = matches if common is None else common & matches
    if common is None:
        return "-"
    for release in order:
        if release in common:
            return release
    return "mixed"


def status(options: Options) -> list[FleetRobotRow]:
    """The table of every robot of the fleet (see the module)."""
    fleet = load(options)
    client = manager_client(fleet)
    try:
        by_robot = robot_nodes(swarm.nodes(client), fleet)
        services = [s for s in swarm.services(client, project_label(fleet)) if plan.LABEL_PROBE not in s.labels]
        tasks = {s.name: swarm.tasks(client, s.name) for s in services}
    finally:
        client.close()
    rows = []
    for robot in fleet.instances:
        mine = [s for s in services if s.labels.get(plan.LABEL_ROBOT) == robot]
        targets = {s.labels.get(plan.LABEL_RELEASE, "") for s in mine}
        target = (targets.pop() if len(targets) == 1 else "mixed") if mine else "-"
        away = bool(offline(robot, by_robot, fleet))
        running = _running(mine, tasks, offline=away)
        healths = {s.labels.get(plan.LABEL_HEALTH, "") for s in mine} - {""}
        health = (healths.pop() if len(healths) == 1 else "mixed") if healths else "-"
        states = ["offline" if away else "online"]
        if mine and running != target:
            states.append("pending")
        changed = max((s.labels.get(plan.LABEL_CHANGED, "") for s in mine), default="") or "-"
        rows.append(FleetRobotRow(robot=robot, running=running, target=target, health=health,
                                  state=", ".join(states), changed=changed))
    _print(options, rows)
    options.report.add(*rows)
    return rows


def _print(options: Options, rows: list[FleetRobotRow]) -> None:
    header = ("ROBOT", "RUNNING", "TARGET", "HEALTH", "STATE", "LAST CHANGE")
    table = [header] + [(r.robot, r.running, r.target, r.health, r.state, r.changed) for r in rows]
    widths = [max(len(row[i]) for row in table) for i in range(len(header))]
    for row in table:
        options.report.out("  ".join(cell.ljust(width) for cell, width in zip(row, widths, strict=True)).rstrip())
