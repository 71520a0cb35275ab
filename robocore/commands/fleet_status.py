"""``fleet status``: one row per robot of the fleet, read from the manager only.

Release running: the release whose images every component's current task runs (``mixed`` while they differ,
``-`` when nothing runs); target: the release its services are set to; health: the last gate's verdict; state:
``online``, ``offline`` (a node of it is not ready), ``unknown`` (the manager, just started, has not heard from a
node of it yet: swarmkit marks every node so until its agent reconnects), ``pending`` (it does not run its target
yet) and ``busy since T`` (``fleet rollout`` holds it back: its update lock or maintenance window,
:mod:`fleet_safe`); last change: when the target last changed; reason (``--json`` only): the last gate's reason in
words; seen (``--json`` only): the ROS nodes and topics the last gate's probe saw, on which release and when
(``null`` when it ran none). All of it comes from the services' labels and tasks and the nodes' states. A robot back
online since a rollout found it offline (its verdict ``pending``) is gated first, once (:mod:`fleet_returned`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from robocore.adapters import swarm
from robocore.commands.fleet_swarm import (
    FleetProject,
    load,
    manager_client,
    manager_line,
    offline,
    project_label,
    robot_nodes,
    unheard,
)
from robocore.commands.support.context import Options
from robocore.plan import gate_graph, naming
from robocore.plan import swarm_services as plan
from robocore.plan.fleet_lock import LABEL_BUSY

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
    state: str  # online | offline | unknown, then pending and busy since T when they apply
    changed: str
    reason: str = ""
    seen: gate_graph.Seen | None = None  # the graph the last gate's probe saw


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


@dataclass(frozen=True)
class Observed:
    """What the manager holds of the fleet at one moment: its robots' nodes, services (probes left out) and their
    tasks. ``fleet status`` and ``fleet page`` read it once per look."""

    by_robot: dict[str, list[swarm.NodeInfo]]
    services: list[swarm.ServiceInfo]
    tasks: dict[str, list[swarm.TaskInfo]]


def observe(fleet: FleetProject) -> Observed:
    """Read the fleet's nodes, services and tasks from the manager (read-only)."""
    client = manager_client(fleet)
    try:
        by_robot = robot_nodes(swarm.nodes(client), fleet)
        services = [s for s in swarm.services(client, project_label(fleet)) if plan.LABEL_PROBE not in s.labels]
        tasks = {s.name: swarm.tasks(client, s.name) for s in services}
    finally:
        client.close()
    return Observed(by_robot=by_robot, services=services, tasks=tasks)


def status(options: Options) -> list[FleetRobotRow]:
    """The table of every robot of the fleet (see the module)."""
    from robocore.commands.fleet_returned import back_and_ungated, gate_returned

    fleet = load(options)
    if options.dry_run:  # the table is the manager's: a dry run contacts nothing
        options.report.plain(manager_line(fleet))
        options.report.plain(f"would read the state of {len(fleet.instances)} robot(s) from the manager, and gate "
                             "those back online since a rollout that found them offline")
        return []
    rows = status_rows(fleet, observe(fleet))
    if back := back_and_ungated([(r.robot, r.health, r.state) for r in rows]):  # seen again: gated once
        gate_returned(fleet, back, options)
        rows = status_rows(fleet, observe(fleet))
    _print(options, rows)
    options.report.add(*rows)
    return rows


def status_rows(fleet: FleetProject, observed: Observed) -> list[FleetRobotRow]:
    """One row per robot of ``fleet``, in fleet-file order, from what the manager held (see the module)."""
    by_robot, services, tasks = observed.by_robot, observed.services, observed.tasks
    rows = []
    for robot in fleet.instances:
        mine = [s for s in services if s.labels.get(plan.LABEL_ROBOT) == robot]
        targets = {s.labels.get(plan.LABEL_RELEASE, "") for s in mine}
        target = (targets.pop() if len(targets) == 1 else "mixed") if mine else "-"
        down = offline(robot, by_robot, fleet)
        away = bool(down)
        running = _running(mine, tasks, offline=away)
        healths = {s.labels.get(plan.LABEL_HEALTH, "") for s in mine} - {""}
        health = (healths.pop() if len(healths) == 1 else "mixed") if healths else "-"
        # a manager that has just started has not heard from the node yet: it does not know, and says so
        states = ["unknown" if away and set(down) <= set(unheard(robot, by_robot, fleet)) else
                  "offline" if away else "online"]
        if mine and running != target:
            states.append("pending")
        if since := max((s.labels.get(LABEL_BUSY, "") for s in mine), default=""):  # held back by fleet rollout
            states.append(f"busy since {since}")
        changed = max((s.labels.get(plan.LABEL_CHANGED, "") for s in mine), default="") or "-"
        reasons = [s.labels[plan.LABEL_REASON] for s in mine if s.labels.get(plan.LABEL_REASON)]
        rows.append(FleetRobotRow(robot=robot, running=running, target=target, health=health,
                                  state=", ".join(states), changed=changed, reason=reasons[0] if reasons else "",
                                  seen=gate_graph.latest(s.labels for s in mine)))
    return rows


def _print(options: Options, rows: list[FleetRobotRow]) -> None:
    header = ("ROBOT", "RUNNING", "TARGET", "HEALTH", "STATE", "LAST CHANGE")
    table = [header] + [(r.robot, r.running, r.target, r.health, r.state, r.changed) for r in rows]
    widths = [max(len(row[i]) for row in table) for i in range(len(header))]
    for row in table:
        options.report.out("  ".join(cell.ljust(width) for cell, width in zip(row, widths, strict=True)).rstrip())
