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

import time
import uuid
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

from robocore.adapters import swarm
from robocore.commands.fleet_swarm import FleetProject, load, manager_client, now, offline, project_label, robot_nodes
from robocore.commands.support.context import Options
from robocore.errors import RobocoreError, UsageError
from robocore.plan import naming
from robocore.plan import swarm_services as plan

if TYPE_CHECKING:
    import docker

#: Seconds between two looks at the tasks while gating.
POLL = 0.5
#: Seconds the output of an ended probe is read again, when it has not reached the manager yet (a robot that has
#: just reconnected sends it late): its verdict says why a robot failed, its exit code alone does not.
PROBE_LOG_WAIT = 5.0
#: Health verdicts kept in the services' labels.
HEALTHY, FAILED, PENDING, ROLLED_BACK = "healthy", "failed", "pending", "rolled-back"
#: States of a task that ended on its own (a crash, an exit, a refusal), not because robocore replaced it.
CRASHED = frozenset({"failed", "complete", "rejected"})


@dataclass(frozen=True)
class RobotOutcome:
    """One robot's outcome in a rollout or rollback."""

    kind: ClassVar[str] = "fleet_robot_change"
    robot: str
    wave: str
    release: str
    verdict: str  # healthy | failed | pending | rolled-back
    reason: str = ""
    seconds: float = 0.0


@dataclass
class Change:
    """A robot being changed and gated (the gate's state)."""

    robot: str
    wave: str
    release: str
    specs: list[plan.ServiceSpec]
    before: dict[str, set[str]]
    started: float
    deadline: float
    running_since: float | None = None
    task_ids: dict[str, str] = field(default_factory=dict)
    probe: str | None = None
    probe_ended: float | None = None  # when the probe's end was first seen with no verdict in its output
    verdict: str | None = None
    reason: str = ""
    ended: float = 0.0


def load_release(fleet: FleetProject, version: str) -> plan.Release:
    """The images of release ``version``, from the record ``release --fleet --tag VERSION`` wrote (by digest; a
    missing, linked-out or malformed record is refused in one line by ``load_release_record``)."""
    from robocore.commands.fleet_release import load_release_record

    record = load_release_record(fleet.project, version)
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


def _set_health(client: docker.DockerClient, specs: Sequence[plan.ServiceSpec], health: str) -> None:
    """Record the gate's verdict in the services' labels (a label-only update restarts nothing)."""
    for spec in specs:
        swarm.set_labels(client, spec.name, {plan.LABEL_HEALTH: health})


class Gate:
    """The health gate of the robots being changed: drives every robot's check from one loop (one connection)."""

    def __init__(self, client: docker.DockerClient, fleet: FleetProject, release: plan.Release | None,
                 releases: dict[str, plan.Release], options: Options) -> None:
        self.client = client
        self.fleet = fleet
        self.releases = releases
        self.health = fleet.fleet.rollout.health
        self.timeouts = fleet.fleet.rollout.timeouts
        self.report = options.report
        self.scripts: dict[str, str] = {}  # probe resource -> its text

    def script(self, robot: str) -> str:
        """The health probe script for ``robot``'s graph (its discovery kind's: rclpy for ROS 2, the master for
        ROS 1)."""
        from robocore import resources

        name = plan.probe_resource(self.fleet.instances[robot])
        if name not in self.scripts:
            self.scripts[name] = resources.read(name).decode()
        return self.scripts[name]

    def run(self, changes: list[Change], deadline: float | None = None) -> None:
        """Decide every change (healthy, failed or pending); a change still undecided at ``deadline`` (a
        ``time.monotonic()`` value: the wave's ``timeouts.wave``) fails as a failed gate does."""
        while any(c.verdict is None for c in changes):
            by_robot = robot_nodes(swarm.nodes(self.client), self.fleet)
            for change in changes:
                if change.verdict is None:
                    self._step(change, by_robot)
            if deadline is not None and time.monotonic() > deadline:
                for change in changes:
                    if change.verdict is None:
                        self._decide(change, FAILED, f"wave {change.wave} not decided within "
                                                     f"{self.timeouts.wave:g} s (timeouts.wave)")
            if any(c.verdict is None for c in changes):
                time.sleep(POLL)

    def _decide(self, change: Change, verdict: str, reason: str = "") -> None:
        change.verdict, change.reason, change.ended = verdict, reason, time.monotonic()
        if change.probe is not None:
            swarm.remove_service(self.client, change.probe)
            change.probe = None

    def _step(self, change: Change, by_robot: dict[str, list[Any]]) -> None:
        down = offline(change.robot, by_robot, self.fleet)
        if down:
            self._decide(change, PENDING, f"offline ({', '.join(down)}): Swarm starts it when it is back")
            return
        clock = time.monotonic()
        current: dict[str, swarm.TaskInfo] = {}
        for spec in change.specs:
            found = swarm.tasks(self.client, spec.name)
            fresh = [t for t in found if t.id not in change.before[spec.name] and t.image == spec.image]
            crashed = [t for t in fresh if t.state in CRASHED]
            if crashed:
                task = crashed[0]
                code = f" with code {task.exit_code}" if task.exit_code is not None else ""
                self._decide(change, FAILED, f"{spec.component} {task.state}{code}"
                             + (f": {task.error}" if task.error else "") + " (restarting)")
                return
            live = [t for t in found if t.desired == "running" and t.image == spec.image]
            if live:
                current[spec.name] = live[0]
        # a service whose update Swarm is still rolling out may yet replace the task seen running
        waiting = [s.component for s in change.specs if s.name not in current
                   or current[s.name].state != "running" or swarm.updating(self.client, s.name)]
        if waiting:
            change.running_since = None
            if clock > change.deadline:
                states = ", ".join(f"{s.component} {current[s.name].state if s.name in current else 'no task'}"
                                   for s in change.specs if s.component in waiting)
                self._decide(change, FAILED, f"not running after {self.timeouts.robot} s ({states})")
            return
        ids = {name: task.id for name, task in current.items()}
        if change.running_since is None or ids != change.task_ids:
            change.running_since, change.task_ids = clock, ids
            return
        if clock - change.running_since < self.health.running:
            return
        if not self.health.nodes and not self.health.heard:
            self._decide(change, HEALTHY)
            return
        self.probe(change, clock)

    def probe(self, change: Change, clock: float) -> None:
        """The first time, start the gate check's probe service on ``change``'s robot; after, once it has ended, decide
        ``change`` healthy or failed by its verdict (its exit code when no verdict came)."""
        if change.probe is None:
            release = self.releases[change.release]
            left = max(change.deadline - clock - 5, 5)
            check = plan.GateCheck(nodes=tuple(self.health.nodes), heard=tuple(self.health.heard), timeout=left)
            spec = plan.probe_service(self.fleet.project, change.robot, self.fleet.instances[change.robot], release,
                                      check, self.script(change.robot), uuid.uuid4().hex[:8])
            ids = swarm.ensure_configs(self.client, spec.configs)
            swarm.apply_service(self.client, spec, ids)
            change.probe = spec.name
            return
        found = swarm.tasks(self.client, change.probe)
        ended = [t for t in found if t.state in swarm.ENDED]
        if not ended:
            if clock > change.deadline + 10:
                self._decide(change, FAILED, f"the health probe did not end within {self.timeouts.robot} s")
            return
        verdict = plan.probe_verdict(swarm.service_logs(self.client, change.probe))
        task = ended[0]
        if verdict is None:
            # its output can reach the manager later than its end (a robot that has just reconnected): read again
            # for a while, then take the exit code as the verdict (it exits 0 only when every node was seen and
            # every topic heard)
            change.probe_ended = change.probe_ended or clock
            if clock - change.probe_ended < PROBE_LOG_WAIT:
                return
            if task.state == "complete" and task.exit_code in (0, None):
                self._decide(change, HEALTHY)
            else:
                self._decide(change, FAILED, f"the health probe printed no verdict ({task.state}"
                             + (f": {task.error}" if task.error else "") + ")")
        elif verdict.get("ok") is True:
            self._decide(change, HEALTHY)
        else:
            missing = ", ".join(str(n) for n in _list(verdict.get("missing")))
            silent = ", ".join(str(t) for t in _list(verdict.get("silent")))
            error = str(verdict.get("error") or "")
            parts = ([error] if error else []) + ([f"nodes missing: {missing}"] if missing else []) \
                + ([f"not heard: {silent}"] if silent else [])
            self._decide(change, FAILED, "; ".join(parts) or "unhealthy")


def _list(value: object) -> list[object]:
    return list(value) if isinstance(value, list) else []


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


def _recorded_release(fleet: FleetProject, robot: str, live: dict[str, swarm.ServiceInfo], *,
                      previous: bool) -> plan.Release | None:
    """From ``robot``'s services' labels: the release it runs (or, with ``previous``, the one it ran before), None
    when there is none."""
    mine = [s for s in live.values() if s.labels.get(plan.LABEL_ROBOT) == robot]
    version_label = plan.LABEL_PREVIOUS if previous else plan.LABEL_RELEASE
    image_label = plan.LABEL_PREVIOUS_IMAGE if previous else plan.LABEL_IMAGE
    versions = {s.labels.get(version_label, "") for s in mine}
    if not mine or versions == {""} or len(versions) != 1:
        return None
    components: dict[str, dict[str, str]] = {}
    base: dict[str, str] = {}
    instance = fleet.instances[robot]
    for service in mine:
        image = service.labels.get(image_label, "") or (service.image if not previous else "")
        component = service.labels.get(naming.LABEL_COMPONENT, "")
        if service.labels.get(naming.LABEL_ROLE) == naming.ROLE_DISCOVERY:
            for host in instance.hosts:
                base.setdefault(host.arch.value, image)
        else:
            try:
                arch = instance.host(instance.component(component).runs_on).arch.value
            except KeyError:
                continue
            components[component] = {arch: image}
    for host in instance.hosts:  # a probe on a host without a discovery server
        if base:
            base.setdefault(host.arch.value, next(iter(base.values())))
    return plan.Release(version=versions.pop(), components=components, base=base)


def _roll_back(client: docker.DockerClient, fleet: FleetProject, changes: list[Change], gate: Gate,
               live: dict[str, swarm.ServiceInfo]) -> list[Change]:
    """Return the robots of ``changes`` to the release they ran before (from ``live``, read before the change)."""
    back: list[Change] = []
    for change in changes:
        previous = _recorded_release(fleet, change.robot, live, previous=False)
        if previous is None:
            for spec in change.specs:  # it ran nothing of this project before: it runs nothing again
                swarm.remove_service(client, spec.name)
            continue
        gate.releases[previous.version] = previous
        for spec in change.specs:
            before = live.get(spec.name)
            if before is not None and before.image != spec.image:
                # made anew rather than updated: Swarm's restart of a crashing task, already scheduled, would race
                # the update and start a second task that the orchestrator then stops again
                swarm.remove_service(client, spec.name)
        # the labels as they were before the change: the failed release is not recorded as the previous one
        back.append(_change(client, fleet, change.robot, change.wave, previous, live, ROLLED_BACK))
    gate.run(back)
    return back


def rollout(options: Options, *, version: str) -> list[RobotOutcome]:
    """Roll ``version`` out wave by wave behind the health gate (see the module)."""
    from robocore.plan.fleet import plan_waves

    if not version:
        raise UsageError("fleet rollout needs the version of a release", hint="robocore fleet rollout v2")
    fleet = load(options)
    release = load_release(fleet, version)
    waves = plan_waves(fleet.fleet)
    report = options.report
    for robot, instance in fleet.instances.items():  # every image known before anything changes
        try:
            plan.robot_services(fleet.project, robot, instance, release)
        except KeyError as missing:
            raise UsageError(f"release {version} has no image of {missing.args[0]}",
                             hint=f"robocore release --tag {version} --fleet") from None
    if options.dry_run:
        for wave in waves:
            report.plain(f"wave {wave.name}: {', '.join(wave.robots)}")
        return []
    client = manager_client(fleet)
    outcomes: list[RobotOutcome] = []
    try:
        gate = Gate(client, fleet, release, {version: release}, options)
        for wave in waves:
            live = _live(client, fleet)
            by_robot = robot_nodes(swarm.nodes(client), fleet)
            report.info(f"wave {wave.name}: {', '.join(wave.robots)}")
            deadline = time.monotonic() + fleet.fleet.rollout.timeouts.wave
            changes = []
            for robot in wave.robots:
                health = PENDING if offline(robot, by_robot, fleet) else ""
                changes.append(_change(client, fleet, robot, wave.name, release, live, health))
            gate.run(changes, deadline)
            for change in changes:
                _set_health(client, change.specs, change.verdict or "")
                report.info(f"  {change.robot}: {change.verdict}" + (f" ({change.reason})" if change.reason else ""))
            outcomes += [_outcome(c) for c in changes]
            failed = [c for c in changes if c.verdict == FAILED]
            if failed:
                back = _roll_back(client, fleet, failed, gate, live)
                for change in back:
                    _set_health(client, change.specs, ROLLED_BACK if change.verdict == HEALTHY else FAILED)
                    report.info(f"  {change.robot}: back on {change.release}: {change.verdict}"
                                + (f" ({change.reason})" if change.reason else ""))
                outcomes += [_outcome(c) for c in back]
                report.add(*outcomes)
                names = ", ".join(f"{c.robot} ({c.reason})" for c in failed)
                later = [w.name for w in waves[wave.index + 1:]]
                raise RobocoreError(f"rollout of {version} stopped in wave {wave.name}: {names} failed the health "
                                    "gate and went back to the previous release"
                                    + (f"; waves not started: {', '.join(later)}" if later else ""))
    finally:
        client.close()
    report.add(*outcomes)
    pending = [o.robot for o in outcomes if o.verdict == PENDING]
    report.notice(f"release {version}: {sum(o.verdict == HEALTHY for o in outcomes)} robot(s) healthy"
                  + (f", pending (offline, Swarm updates them when they are back): {', '.join(pending)}"
                     if pending else ""))
    return outcomes


def rollback(options: Options, *, robots: Sequence[str]) -> list[RobotOutcome]:
    """Return ``robots`` (default: every robot of the fleet) to the release each ran before, behind the gate."""
    fleet = load(options)
    unknown = [r for r in robots if r not in fleet.instances]
    if unknown:
        raise UsageError(f"unknown robot(s): {', '.join(unknown)} (known: {', '.join(fleet.instances)})")
    chosen = list(robots) or list(fleet.instances)
    client = manager_client(fleet)
    try:
        live = _live(client, fleet)
        releases = {}
        problems = []
        for robot in chosen:
            previous = _recorded_release(fleet, robot, live, previous=True)
            if previous is None:
                problems.append(f"{robot}: no previous release recorded")
            else:
                releases[robot] = previous
        if problems:
            raise UsageError("; ".join(problems))
        if options.dry_run:
            for robot, previous in releases.items():
                options.report.plain(f"{robot}: back to {previous.version}")
            return []
        gate = Gate(client, fleet, None, {r.version: r for r in releases.values()}, options)
        by_robot = robot_nodes(swarm.nodes(client), fleet)
        changes = [_change(client, fleet, robot, "rollback", previous, live,
                           PENDING if offline(robot, by_robot, fleet) else "")
                   for robot, previous in releases.items()]
        gate.run(changes)
        for change in changes:
            _set_health(client, change.specs, change.verdict or "")
            options.report.info(f"{change.robot}: {change.release}: {change.verdict}"
                                + (f" ({change.reason})" if change.reason else ""))
    finally:
        client.close()
    outcomes = [_outcome(c) for c in changes]
    options.report.add(*outcomes)
    failed = [o for o in outcomes if o.verdict == FAILED]
    if failed:
        raise RobocoreError("rollback: " + "; ".join(f"{o.robot} failed the health gate ({o.reason})"
                                                     for o in failed))
    return outcomes
