"""``fleet rollout VERSION`` and ``fleet rollback [ROBOT...]``: robots moved wave by wave, each behind a health gate.

robocore drives the waves itself rather than leaving them to Swarm, whose own update rolls back per service (not
per robot) and stalls on an offline node. For each wave:

1. every robot of the wave whose nodes are ready gets its services updated to the release (stop-first: the old
   container stops before the new one starts, so never two copies of a ROS node); a robot whose node is down is
   reported **pending**: its services get the target spec anyway, so Swarm starts it when the node comes back,
   with no operator action, and its running containers are left alone meanwhile;
2. the gate, per robot: every container of the release running, with no task of it ended (no crash, no restart)
   for ``rollout.health.running`` seconds; then a probe on the robot (a one-shot service on its first discovery
   server's host, an observer of its graph) sees the declared nodes and hears the declared topics;
3. a robot that fails its gate (or does not pass it within ``timeouts.robot``) stops the rollout: the failed
   robots return to their previous release (and are gated again, to say whether they are back and heard), and
   no robot of a later wave is changed.

The target and previous release (and images) of every service are kept in its labels, so ``fleet status`` and
``fleet rollback`` work from any machine that reaches the manager.
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING, ClassVar

from robocore.adapters import swarm
from robocore.commands.fleet_gate import (
    FAILED,
    HEALTHY,
    PENDING,
    ROLLED_BACK,
    Change,
    Gate,
    set_health,
)
from robocore.commands.fleet_swarm import (
    FleetProject,
    load,
    manager_client,
    manager_line,
    now,
    offline,
    project_label,
    recorded_release,
    robot_nodes,
)
from robocore.commands.support.context import Options
from robocore.errors import RobocoreError, UsageError
from robocore.plan import fleet_lock
from robocore.plan import swarm_services as plan

if TYPE_CHECKING:
    import docker


@dataclass(frozen=True)
class RobotOutcome:
    """One robot's outcome in a rollout or rollback."""

    kind: ClassVar[str] = "fleet_robot_change"
    robot: str
    wave: str
    release: str
    verdict: str  # healthy | failed | pending | rolled-back | busy (fleet_lock.BUSY: held back past timeouts.busy)
    reason: str = ""
    seconds: float = 0.0


def load_release(fleet: FleetProject, version: str) -> plan.Release:
    """The images of release ``version``, from the record ``release --fleet --tag VERSION`` wrote (by digest; a
    missing, linked-out or malformed record is refused in one line by ``load_release_record``)."""
    from robocore.commands.fleet_release import load_release_record

    record = load_release_record(fleet.project, version, fleet.fleet.registry_for(fleet.project.robot))
    return plan.Release(version=record.version, components=record.components, base=record.base)


def _live(client: docker.DockerClient, fleet: FleetProject) -> dict[str, swarm.ServiceInfo]:
    return {s.name: s for s in swarm.services(client, project_label(fleet)) if plan.LABEL_PROBE not in s.labels}


def _labelled(spec: plan.ServiceSpec, version: str, live: swarm.ServiceInfo | None, health: str) -> plan.ServiceSpec:
    """``spec`` with its release labels: the release it had becomes the previous one (unless it is the same)."""
    if live is None:
        return plan.release_labels(spec, version=version, previous="", previous_image="", changed=now(),
                                   health=health)
    labels = live.labels
    current = labels.get(plan.LABEL_RELEASE, "")
    if current == version and live.image == spec.image:
        return plan.release_labels(spec, version=version, previous=labels.get(plan.LABEL_PREVIOUS, ""),
                                   previous_image=labels.get(plan.LABEL_PREVIOUS_IMAGE, ""),
                                   changed=labels.get(plan.LABEL_CHANGED, now()), health=health)
    return plan.release_labels(spec, version=version, previous=current, previous_image=live.image, changed=now(),
                               health=health)


def _apply(client: docker.DockerClient, specs: Sequence[plan.ServiceSpec]) -> dict[str, set[str]]:
    """Create or update ``specs``; return each service's task ids from before the change."""
    before = {s.name: {t.id for t in swarm.tasks(client, s.name)} for s in specs}
    ids = swarm.ensure_configs(client, tuple(c for s in specs for c in s.configs))
    for spec in specs:
        swarm.apply_service(client, spec, ids)
    return before


def _change(client: docker.DockerClient, fleet: FleetProject, robot: str, wave: str, release: plan.Release,
            live: dict[str, swarm.ServiceInfo], health: str) -> Change:
    """Update ``robot``'s services to ``release`` (stop-first) and return the gate's state for it."""
    specs = plan.robot_services(fleet.project, robot, fleet.instances[robot], release)
    specs = [_labelled(s, release.version, live.get(s.name), health) for s in specs]
    before = _apply(client, specs)
    start = time.monotonic()
    return Change(robot=robot, wave=wave, release=release.version, specs=specs, before=before, started=start,
                   deadline=start + fleet.fleet.rollout.timeouts.robot)


def _outcome(change: Change) -> RobotOutcome:
    return RobotOutcome(robot=change.robot, wave=change.wave, release=change.release, verdict=change.verdict or "",
                        reason=change.reason, seconds=round((change.ended or time.monotonic()) - change.started, 1))


def roll_back(client: docker.DockerClient, fleet: FleetProject, changes: list[Change], gate: Gate,
               live: dict[str, swarm.ServiceInfo]) -> list[Change]:
    """Return the robots of ``changes`` to the release they ran before (from ``live``, read before the change)."""
    back: list[Change] = []
    previous = {c.robot: recorded_release(fleet, c.robot, live, previous=False) for c in changes}
    # made anew rather than updated: Swarm's restart of a crashing task, already scheduled, would race an update and
    # start a second task that the orchestrator then stops again. Removed first, and made anew only once their old
    # containers have stopped (stop-first, as an update is): never the failed and the previous node side by side.
    # A robot that ran nothing of this project before runs nothing again.
    left = swarm.remove_stopped(client, [spec.name for c in changes for spec in c.specs
                                         if previous[c.robot] is None or (spec.name in live
                                                                          and live[spec.name].image != spec.image)])
    if left:  # said, not hidden: the previous release starts beside a container that would not stop
        gate.report.warn(f"{len(left)} removed task(s) had not stopped after {swarm.STOPPED_WAIT:g} s: the previous "
                         "release is started anyway")
    for change in changes:
        release = previous[change.robot]
        if release is None:
            continue
        gate.releases[release.version] = release
        # the labels as they were before the change: the failed release is not recorded as the previous one
        back.append(_change(client, fleet, change.robot, change.wave, release, live, ROLLED_BACK))
    gate.run(back)
    return back


def rollout(options: Options, *, version: str, force: bool = False) -> list[RobotOutcome]:
    """Roll ``version`` out wave by wave behind the health gate, each robot asked first (:mod:`fleet_safe`; not
    with ``force``); see the module."""
    from robocore.commands.fleet_safe import Asker, busy_line
    from robocore.plan.fleet import plan_waves

    if not version:
        raise UsageError("fleet rollout needs the version of a release", hint="robocore fleet rollout v2")
    from robocore.commands.fleet_release import record_path

    fleet = load(options)
    waves = plan_waves(fleet.fleet)
    report = options.report
    if options.dry_run and not os.path.lexists(record_path(fleet.project, version)):  # the waves, before a release
        report.plain(manager_line(fleet))
        for wave in waves:
            report.plain(f"wave {wave.name}: {', '.join(wave.robots)}")
        report.plain(f"release {version} is not made yet (robocore release --fleet --tag {version}): its images are "
                     "not checked")
        return []
    release = load_release(fleet, version)
    # every image known before anything changes: a robot's images depend only on its hosts' arches (robot.yaml's
    # components on robot.yaml's hosts), so one robot of each set of arches is planned, not 10,000 alike
    alike: dict[tuple[str, ...], str] = {}
    for robot, instance in fleet.instances.items():
        alike.setdefault(tuple(host.arch.value for host in instance.hosts), robot)
    for robot in alike.values():
        try:
            plan.robot_services(fleet.project, robot, fleet.instances[robot], release)
        except KeyError as missing:
            raise UsageError(f"release {version} has no image of {missing.args[0]}",
                             hint=f"robocore release --tag {version} --fleet") from None
    if options.dry_run:
        report.plain(manager_line(fleet))
        for wave in waves:
            report.plain(f"wave {wave.name}: {', '.join(wave.robots)}")
        return []
    client = manager_client(fleet)
    outcomes: list[RobotOutcome] = []
    try:
        from robocore.commands.fleet_bytes import report_bytes
        from robocore.commands.fleet_manager import clear_probes, settle

        settle(client, fleet, report)  # a manager that has just restarted: see fleet_manager
        report.add(*report_bytes(client, fleet, release, list(fleet.instances), report))
        gate = Gate(client, fleet, release, {version: release}, options)
        for wave in waves:
            live = _live(client, fleet)
            by_robot = robot_nodes(swarm.nodes(client), fleet)
            report.info(f"wave {wave.name}: {', '.join(wave.robots)}")
            deadline = time.monotonic() + fleet.fleet.rollout.timeouts.wave
            start = partial(_change, client, fleet, wave=wave.name, release=release, live=live)
            with Asker(client, fleet, wave.name, release, start, report, force=force) as asker:
                changes = asker.first(wave.robots, by_robot)
                gate.run(changes, deadline, asker)
            for change in changes:
                set_health(client, change, change.verdict or "", change.reason)
                report.info(f"  {change.robot}: {change.verdict}" + (f" ({change.reason})" if change.reason else ""))
            outcomes += [_outcome(c) for c in changes] + asker.outcomes(RobotOutcome)
            if asker.given_up and all(c.verdict != HEALTHY for c in changes):  # the release untried: stop
                report.add(*outcomes)
                raise RobocoreError(f"rollout of {version} stopped in wave {wave.name}: {busy_line(outcomes)}")
            failed = [c for c in changes if c.verdict == FAILED]
            if failed:
                back = roll_back(client, fleet, failed, gate, live)
                why = {c.robot: c.reason for c in failed}
                for change in back:  # the reason kept is the failure's, and the way back's when that failed too
                    set_health(client, change, ROLLED_BACK if change.verdict == HEALTHY else FAILED,
                                why[change.robot] + (f"; back on {change.release}: {change.reason}" if change.reason
                                                     else ""))
                    report.info(f"  {change.robot}: back on {change.release}: {change.verdict}"
                                + (f" ({change.reason})" if change.reason else ""))
                outcomes += [_outcome(c) for c in back]
                report.add(*outcomes)
                names = ", ".join(f"{c.robot} ({c.reason})" for c in failed)
                later = [w.name for w in waves[wave.index + 1:]]
                raise RobocoreError(f"rollout of {version} stopped in wave {wave.name}: {names} failed the health "
                                    "gate and went back to the previous release"
                                    + (f"; waves not started: {', '.join(later)}" if later else ""))
        clear_probes(client, fleet)  # what a run that was cut off left, ended by now
    finally:
        client.close()
    report.add(*outcomes)
    pending = [o.robot for o in outcomes if o.verdict == PENDING]
    report.notice(f"release {version}: {sum(o.verdict == HEALTHY for o in outcomes)} robot(s) healthy"
                  + (f", pending (offline, Swarm updates them when they are back): {', '.join(pending)}"
                     if pending else ""))
    if any(o.verdict == fleet_lock.BUSY for o in outcomes):
        raise RobocoreError(f"release {version}: {busy_line(outcomes)}")
    return outcomes


def rollback(options: Options, *, robots: Sequence[str]) -> list[RobotOutcome]:
    """Return ``robots`` (default: every robot of the fleet) to the release each ran before, behind the gate."""
    fleet = load(options)
    unknown = [r for r in robots if r not in fleet.instances]
    if unknown:
        raise UsageError(f"unknown robot(s): {', '.join(unknown)} (known: {', '.join(fleet.instances)})")
    chosen = list(robots) or list(fleet.instances)
    if options.dry_run:  # the previous releases are in the manager's labels: a dry run contacts nothing
        options.report.plain(manager_line(fleet))
        options.report.plain(f"would return {', '.join(chosen)} to the release each ran before (read from the manager)")
        return []
    client = manager_client(fleet)
    try:
        from robocore.commands.fleet_manager import clear_probes, settle

        settle(client, fleet, options.report)
        live = _live(client, fleet)
        found = {robot: recorded_release(fleet, robot, live, previous=True) for robot in chosen}
        if problems := [f"{robot}: no previous release recorded" for robot, known in found.items() if known is None]:
            raise UsageError("; ".join(problems))
        releases = {robot: known for robot, known in found.items() if known is not None}
        gate = Gate(client, fleet, None, {r.version: r for r in releases.values()}, options)
        by_robot = robot_nodes(swarm.nodes(client), fleet)
        changes = [_change(client, fleet, robot, "rollback", previous, live,
                           PENDING if offline(robot, by_robot, fleet) else "")
                   for robot, previous in releases.items()]
        gate.run(changes)
        for change in changes:
            set_health(client, change, change.verdict or "", change.reason)
            options.report.info(f"{change.robot}: {change.release}: {change.verdict}"
                                + (f" ({change.reason})" if change.reason else ""))
        clear_probes(client, fleet)
    finally:
        client.close()
    outcomes = [_outcome(c) for c in changes]
    options.report.add(*outcomes)
    failed = [o for o in outcomes if o.verdict == FAILED]
    if failed:
        raise RobocoreError("rollback: " + "; ".join(f"{o.robot} failed the health gate ({o.reason})"
                                                     for o in failed))
    return outcomes
