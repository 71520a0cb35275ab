"""Robots seen again: a robot that was offline during a rollout (its verdict ``pending``) is gated once it is back.

Swarm gives a reconnected node its services' current spec on its own, so such a robot converges to its target with
no command; but nothing had gated it, and its health would stay ``pending`` for good. ``fleet status`` gates it the
first time it sees it back: online, running its target, its last verdict ``pending``. The gate is the rollout's
(every container running for ``health.running``, then the probe's nodes and topics within ``timeouts.heard``), run
on what the robot runs now, changing nothing of it; its verdict and reason go to the services' labels, as a
rollout's do, so every later ``fleet status`` and ``fleet page`` shows it. A robot that fails is reported ``failed``
with the gate's reason and left as it is: a status command changes no release (``fleet rollback ROBOT`` sends it
back).

Why ``fleet status`` and not only the next ``fleet rollout``: status is the first command an operator runs after a
robot is back, and a rollout may be days away (a rollout gates every robot of its waves anyway). It costs a probe,
and ``health.running`` plus a few seconds, only when such a robot exists, once: its label then says healthy or
failed. ``fleet page`` stays a read-only view.
"""

from __future__ import annotations

import time

from robocore.adapters import swarm
from robocore.commands.fleet_gate import PENDING, Change, Gate, set_health
from robocore.commands.fleet_swarm import FleetProject, manager_client, project_label, recorded_release
from robocore.commands.support.context import Options
from robocore.plan import swarm_services as plan


def back_and_ungated(rows: list[tuple[str, str, str]]) -> list[str]:
    """The robots of ``rows`` (robot, health, state as ``fleet status`` shows them) that are back and not gated
    since: their last verdict ``pending``, now online and running their target (no other state)."""
    return [robot for robot, health, state in rows if health == PENDING and state == "online"]


def gate_returned(fleet: FleetProject, robots: list[str], options: Options) -> list[Change]:
    """Gate ``robots`` on the release each runs (read from its services' labels), changing nothing of them; write
    each verdict to its services' labels and say it. Returns the decided changes."""
    report = options.report
    client = manager_client(fleet)
    try:
        live = {s.name: s for s in swarm.services(client, project_label(fleet)) if plan.LABEL_PROBE not in s.labels}
        gate = Gate(client, fleet, None, {}, options)
        changes = []
        for robot in robots:
            release = recorded_release(fleet, robot, live, previous=False)
            if release is None:
                continue
            gate.releases[release.version] = release
            specs = plan.robot_services(fleet.project, robot, fleet.instances[robot], release)
            before = {s.name: {t.id for t in swarm.tasks(client, s.name)} for s in specs}  # old crashes do not count
            start = time.monotonic()
            changes.append(Change(robot=robot, wave="back", release=release.version, specs=specs, before=before,
                                  started=start, deadline=start + fleet.fleet.rollout.timeouts.robot))
            report.info(f"{robot}: back online on {release.version}, not gated since: gating it")
        gate.run(changes)
        for change in changes:
            set_health(client, change, change.verdict or "", change.reason)
            report.info(f"  {change.robot}: {change.verdict}" + (f" ({change.reason})" if change.reason else ""))
    finally:
        client.close()
    return changes
