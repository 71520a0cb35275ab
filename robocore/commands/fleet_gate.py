"""The rollout's health gate: each robot changed (or found again) is decided healthy, failed or pending.

Per robot: every container of its release running, with no task of it ended (no crash, no restart) for
``rollout.health.running`` seconds; then a probe on the robot (a one-shot service on its first discovery server's
host, an observer of its graph) sees the declared nodes and hears the declared topics. Three bounds apply:

- ``timeouts.robot``, from the change: the whole of it, a first pull of the release included;
- ``timeouts.heard``, from the moment every container of the robot runs: how long its graph may take to show the
  nodes and carry the topics. A robot that runs but is not heard (a node on the wrong topic) is decided on this
  shorter bound, not on the robot's, which must also cover a pull;
- the wave's ``timeouts.wave``, given to :meth:`Gate.run` by the rollout.

While it waits the gate says, about every :data:`PROGRESS` seconds for each robot not yet decided, what it waits
for (the containers not running yet, the nodes not yet seen, the topics not yet heard) and how long of which
bound has gone: a rollout is never silent for long.
"""

from __future__ import annotations

import time
import uuid
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from robocore.adapters import swarm
from robocore.commands.fleet_gate_record import record_gate
from robocore.commands.fleet_swarm import FleetProject, offline, robot_nodes
from robocore.commands.support.context import Options
from robocore.errors import DockerError
from robocore.plan import swarm_services as plan
from robocore.plan.gate_reasons import task_ended

if TYPE_CHECKING:
    import docker

    from robocore.commands.fleet_safe import Asker

#: Seconds between two looks at the tasks while gating.
POLL = 0.5
#: Seconds the output of an ended probe is read again, when it has not reached the manager yet (a robot that has
#: just reconnected sends it late): its verdict says why a robot failed, its exit code alone does not.
PROBE_LOG_WAIT = 5.0
#: Health verdicts kept in the services' labels.
HEALTHY, FAILED, PENDING, ROLLED_BACK = "healthy", "failed", "pending", "rolled-back"
#: States of a task that ended on its own (a crash, an exit, a refusal), not because robocore replaced it.
CRASHED = frozenset({"failed", "complete", "rejected"})
#: Seconds between two lines saying what the gate waits for, per robot not yet decided: often enough that a rollout
#: is never long silent, seldom enough that ten robots' lines stay readable.
PROGRESS = 10.0
#: The least time a probe is given to see the graph (its own start-up on the robot aside), when the heard bound is
#: (nearly) gone by the time the containers have run for ``health.running``.
PROBE_MIN = 5.0


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
    graph: dict[str, object] | None = None  # the probe's verdict: the graph it saw (fleet_gate_record keeps it)
    verdict: str | None = None
    reason: str = ""
    ended: float = 0.0
    waited: float = 0.0  # seconds it was held back before its change (fleet_safe): not counted in the wave's time
    heard_by: float | None = None  # the heard bound's end: timeouts.heard after its containers were first all running
    waiting: str = ""  # what the gate waits for, in words (its last look)
    said: float | None = None  # when the gate last said what it waits for

    def __post_init__(self) -> None:
        if self.said is None:
            self.said = self.started


def set_health(client: docker.DockerClient, change: Change, health: str, reason: str) -> None:
    """Record the gate's verdict, its reason and the graph its probe saw in the robot's service labels
    (:func:`fleet_gate_record.record_gate`: a label-only update restarts nothing), so that ``fleet status --json`` and
    ``fleet page`` say why, and what was live, from any machine."""
    record_gate(client, change.specs, health, reason, change.graph)


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

    def run(self, changes: list[Change], deadline: float | None = None, asker: Asker | None = None) -> None:
        """Decide every change (healthy, failed or pending); a change still undecided at ``deadline`` (a
        ``time.monotonic()`` value: the wave's ``timeouts.wave``, plus the time it was held back) fails as a failed
        gate does. While ``asker`` holds robots back, the changes it starts are added to ``changes`` and gated."""
        while any(c.verdict is None for c in changes) or (asker is not None and asker.waiting):
            by_robot = robot_nodes(swarm.nodes(self.client), self.fleet)
            for change in changes:
                if change.verdict is None:
                    self._step(change, by_robot)
            for change in changes:
                if deadline is not None and change.verdict is None and time.monotonic() > deadline + change.waited:
                    self._decide(change, FAILED, f"wave {change.wave} not decided within {self.timeouts.wave:g} s "
                                                 "(timeouts.wave)")
            changes += asker.step(by_robot) if asker is not None else []
            self.say(changes)
            if asker is not None:
                asker.say(PROGRESS)
            if any(c.verdict is None for c in changes) or (asker is not None and asker.waiting):
                time.sleep(POLL)

    def say(self, changes: list[Change]) -> None:
        """Say, about every :data:`PROGRESS` seconds for each change not yet decided, what the gate waits for (with
        the nodes and topics its probe has not seen or heard yet, read from the probe's progress lines)."""
        clock = time.monotonic()
        for change in changes:
            if change.verdict is not None or not change.waiting or clock - (change.said or 0.0) < PROGRESS:
                continue
            if change.probe is not None:
                try:
                    progress = plan.probe_progress(swarm.service_logs(self.client, change.probe))
                    change.waiting = self._graph_wait(progress, clock, change)
                except (DockerError, OSError):  # a robot whose logs do not reach the manager: said as last time
                    pass
            self.report.info(f"  {change.robot}: {change.waiting}")
            change.said = clock

    def _graph_wait(self, progress: dict[str, list[str]] | None, clock: float, change: Change) -> str:
        """What the probe of ``change`` waits for, from its last ``progress`` line (None: none yet)."""
        heard_by = change.heard_by if change.heard_by is not None else clock + self.timeouts.heard
        bound = f"({clock - (heard_by - self.timeouts.heard):.0f} s of {self.timeouts.heard:g} s, timeouts.heard)"
        if progress is None:
            wanted = ([f"see {', '.join(self.health.nodes)}"] if self.health.nodes else []) \
                + ([f"hear {', '.join(self.health.heard)}"] if self.health.heard else [])
            return f"its probe starts, to {' and '.join(wanted)} {bound}"
        missing, silent = progress.get("missing", []), progress.get("silent", [])
        parts = ([f"not yet seen: {', '.join(missing)}"] if missing else []) \
            + ([f"not yet heard: {', '.join(silent)}"] if silent else [])
        return f"its graph: {'; '.join(parts) or 'all seen and heard'} {bound}"

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
            if crashed := [t for t in fresh if t.state in CRASHED]:
                task = crashed[0]
                self._decide(change, FAILED, task_ended(spec.component, task.state, task.exit_code, task.error,
                                                        task.hint))
                return
            live = [t for t in found if t.desired == "running" and t.image == spec.image]
            if live:
                current[spec.name] = live[0]
        # a service whose update Swarm is still rolling out may yet replace the task seen running
        waiting = [s.component for s in change.specs if s.name not in current
                   or current[s.name].state != "running" or swarm.updating(self.client, s.name)]
        if waiting:
            change.running_since = None
            states = ", ".join(f"{s.component} {current[s.name].state if s.name in current else 'no task'}"
                               for s in change.specs if s.component in waiting)
            if clock > change.deadline:
                self._decide(change, FAILED, f"not running after {self.timeouts.robot:g} s ({states})")
            change.waiting = (f"waits for its containers to run: {states} ({clock - change.started:.0f} s of "
                              f"{self.timeouts.robot:g} s, timeouts.robot)")
            return
        ids = {name: task.id for name, task in current.items()}
        if change.running_since is None or ids != change.task_ids:
            change.running_since, change.task_ids = clock, ids
            if change.heard_by is None:  # the heard bound counts from the first time every container runs
                change.heard_by = clock + self.timeouts.heard
        if clock - change.running_since < self.health.running:
            change.waiting = (f"every container running for {clock - change.running_since:.0f} s of "
                              f"{self.health.running:g} s (health.running)")
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
            heard_by = change.heard_by if change.heard_by is not None else clock + self.timeouts.heard
            left = max(min(change.deadline - clock - 5, heard_by - clock), PROBE_MIN)
            check = plan.GateCheck(nodes=tuple(self.health.nodes), heard=tuple(self.health.heard), timeout=left)
            spec = plan.probe_service(self.fleet.project, change.robot, self.fleet.instances[change.robot], release,
                                      check, self.script(change.robot), uuid.uuid4().hex[:8])
            ids = swarm.ensure_configs(self.client, spec.configs)
            swarm.apply_service(self.client, spec, ids)
            change.probe = spec.name
            change.waiting = self._graph_wait(None, clock, change)
            return
        found = swarm.tasks(self.client, change.probe)
        ended = [t for t in found if t.state in swarm.ENDED]
        if not ended:
            if clock > change.deadline + 10:
                self._decide(change, FAILED, f"the health probe did not end within {self.timeouts.robot:g} s")
            return
        verdict = plan.probe_verdict(swarm.service_logs(self.client, change.probe))
        change.graph = verdict
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
                             + (f": {task.why}" if task.error else "") + ")")
        elif verdict.get("ok") is True:
            self._decide(change, HEALTHY)
        else:
            self._decide(change, FAILED, plan.verdict_reason(verdict))


