"""Updates only at a safe moment: each robot of a wave is asked before ``fleet rollout`` touches it.

A robot is held back (deferred) while its maintenance window is closed (``rollout.windows``) or while a node of it
holds its update lock (``/robocore/update_lock``, :mod:`robocore.plan.fleet_lock`), asked by a one-shot probe
service on the robot through the manager, again every :data:`~robocore.plan.fleet_lock.LOCK_POLL` seconds after
each answer. The others of its wave go on meanwhile; a held robot is changed (and gated) as soon as it is free, and
its services say ``busy since`` while it waits (a label, so ``fleet status`` shows it from any machine). A robot
still held after ``rollout.timeouts.busy`` is left as it is, reported ``busy``; the rollout goes on with the next
wave, unless no robot of the wave was changed at all (then nothing of the release was tested: it stops). An
offline robot is not asked (it cannot be): it is pending, as before. ``--force`` asks nothing, and says so.
"""

from __future__ import annotations

import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import TYPE_CHECKING, Any

from robocore.adapters import swarm
from robocore.commands.fleet_swarm import FleetProject, offline, project_label
from robocore.plan import fleet_lock
from robocore.plan import swarm_services as plan
from robocore.plan.fleet_windows import window_state, windows_of

if TYPE_CHECKING:
    import docker

    from robocore.commands.fleet_gate import Change
    from robocore.commands.fleet_rollout import RobotOutcome
    from robocore.commands.support.reporting import Reporter

#: Seconds an ended lock probe's output is read again before its end is taken as "could not tell".
ANSWER_WAIT = 5.0


@dataclass
class Held:
    """A robot of the wave not yet changed: since when it is held, why, and its lock probe under way."""

    robot: str
    since: float
    reason: str = ""
    probe: str | None = None
    probe_started: float = 0.0
    probe_ended: float | None = None
    next_ask: float = 0.0
    labelled: str = ""  # the reason last written to its services' labels
    said: float = 0.0  # when it was last said to be held


class Asker:
    """Asks the robots of one wave before they are changed; a :class:`~robocore.commands.fleet_gate.Gate` calls
    :meth:`step` on each of its looks while :attr:`waiting`, and gates the changes it returns."""

    def __init__(self, client: docker.DockerClient, fleet: FleetProject, wave: str, release: plan.Release,
                 start: Callable[..., Change], report: Reporter, *, force: bool,
                 clock: Callable[[], datetime] = lambda: datetime.now(timezone.utc)) -> None:
        self.client, self.fleet, self.wave, self.release = client, fleet, wave, release
        self.start, self.report, self.force, self.clock = start, report, force, clock
        self.busy = fleet.fleet.rollout.timeouts.busy
        self.began = time.monotonic()
        self.held: dict[str, Held] = {}
        self.given_up: list[Held] = []
        self.changed = 0
        self.scripts: dict[str, str] = {}

    def __enter__(self) -> Asker:
        return self

    def __exit__(self, *_: object) -> None:
        for held in self.held.values():
            self._drop_probe(held)

    @property
    def waiting(self) -> bool:
        """True while a robot of the wave is still held (or being asked)."""
        return bool(self.held)

    def first(self, robots: tuple[str, ...], by_robot: dict[str, list[Any]]) -> list[Change]:
        """The changes that start at once: every robot with ``--force``, offline robots (pending: they cannot be
        asked); the others are asked (:meth:`step`)."""
        if self.force:
            self.report.notice(f"--force: wave {self.wave} updated without asking its robots' update lock "
                               "or maintenance window")
        changes = []
        for robot in robots:
            if self.force or offline(robot, by_robot, self.fleet):
                changes.append(self._go(robot, "pending" if offline(robot, by_robot, self.fleet) else ""))
            else:
                self.held[robot] = Held(robot=robot, since=time.monotonic())
        return changes + self.step(by_robot)

    def step(self, by_robot: dict[str, list[Any]]) -> list[Change]:
        """One look at every held robot: the changes of those now free."""
        started = []
        for held in list(self.held.values()):
            clock = time.monotonic()
            if offline(held.robot, by_robot, self.fleet):  # lost while held: pending, as any offline robot
                self._drop_probe(held)
                del self.held[held.robot]
                started.append(self._go(held.robot, "pending"))
                continue
            window = window_state(windows_of(self.fleet.fleet, held.robot), self.clock())
            if window is not None and not window.open:
                self._drop_probe(held)
                self._hold(held, fleet_lock.hold_reason(window, False))
            elif held.probe is None and clock >= held.next_ask:
                self._ask(held)
            elif held.probe is not None:
                answer = self._answer(held, clock)
                if answer is not None:
                    reason = fleet_lock.hold_reason(window, *answer)
                    if not reason:
                        del self.held[held.robot]
                        started.append(self._go(held.robot, ""))
                        continue
                    self._hold(held, reason)
            if fleet_lock.past_busy(clock - held.since, self.busy) and held.reason:
                self._give_up(held)
        return started

    def say(self, every: float) -> None:
        """Say again, every ``every`` seconds, why each robot still held is held and for how long of its bound."""
        clock = time.monotonic()
        for held in self.held.values():
            if held.reason and clock - max(held.said, held.since) >= every:
                self.report.info(f"  {held.robot}: still deferred: {held.reason} ({clock - held.since:.0f} s of "
                                 f"{self.busy:g} s, timeouts.busy)")
                held.said = clock

    def outcomes(self, outcome: type[RobotOutcome]) -> list[RobotOutcome]:
        """The robots left as they were, as outcomes (verdict ``busy``)."""
        return [outcome(robot=h.robot, wave=self.wave, release=self.release.version, verdict=fleet_lock.BUSY,
                        reason=h.reason, seconds=round(time.monotonic() - h.since, 1)) for h in self.given_up]

    def _go(self, robot: str, health: str) -> Change:
        change = self.start(robot, health=health)
        change.waited = time.monotonic() - self.began
        self.changed += 1
        return change

    def _services(self, robot: str) -> list[str]:
        return [s.name for s in swarm.services(self.client, project_label(self.fleet))
                if s.labels.get(plan.LABEL_PROBE) is None and s.labels.get(plan.LABEL_ROBOT) == robot]

    def _hold(self, held: Held, reason: str) -> None:
        """Keep ``held`` back for ``reason``: said once, and written to its services (``busy since``)."""
        held.reason = reason
        if reason == held.labelled:
            return
        first = not held.labelled
        held.labelled = reason
        since = datetime.now(timezone.utc).timestamp() - (time.monotonic() - held.since)
        stamp = datetime.fromtimestamp(since, timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
        self.report.info(f"  {held.robot}: {'deferred' if first else 'still deferred'}: {reason}")
        held.said = time.monotonic()
        for name in self._services(held.robot):
            swarm.set_labels(self.client, name, {fleet_lock.LABEL_BUSY: stamp, plan.LABEL_REASON: reason})

    def _give_up(self, held: Held) -> None:
        self._drop_probe(held)
        del self.held[held.robot]
        held.reason = (f"not updated to {self.release.version}: {held.reason} for more than {self.busy:g} s "
                       "(rollout.timeouts.busy)")
        self.given_up.append(held)
        self.report.info(f"  {held.robot}: busy ({held.reason})")
        for name in self._services(held.robot):
            swarm.set_labels(self.client, name, {fleet_lock.LABEL_BUSY: "", plan.LABEL_HEALTH: fleet_lock.BUSY,
                                                 plan.LABEL_REASON: held.reason})

    def _ask(self, held: Held) -> None:
        from robocore import resources

        instance = self.fleet.instances[held.robot]
        name = fleet_lock.lock_resource(instance)
        if name not in self.scripts:
            self.scripts[name] = resources.read(name).decode()
        spec = fleet_lock.lock_probe_service(self.fleet.project, held.robot, instance, self.release,
                                             self.scripts[name], uuid.uuid4().hex[:8])
        swarm.apply_service(self.client, spec, swarm.ensure_configs(self.client, spec.configs))
        held.probe, held.probe_started, held.probe_ended = spec.name, time.monotonic(), None

    def _answer(self, held: Held, clock: float) -> tuple[bool | None, str] | None:
        """The lock probe's answer once it has ended (None while it runs)."""
        assert held.probe is not None
        ended = [t for t in swarm.tasks(self.client, held.probe) if t.state in swarm.ENDED]
        if not ended:
            if clock - held.probe_started > self.fleet.fleet.rollout.timeouts.robot:
                self._drop_probe(held)
                return None, f"the update-lock probe did not end within {self.fleet.fleet.rollout.timeouts.robot} s"
            return None
        output = swarm.service_logs(self.client, held.probe)
        locked, error = fleet_lock.lock_answer(output)
        if locked is None and not error.startswith("cannot"):
            held.probe_ended = held.probe_ended or clock
            if clock - held.probe_ended < ANSWER_WAIT:  # its output may reach the manager after its end
                return None
            task = ended[0]  # no output after the wait: its exit code answers (0 free, 1 locked)
            locked, error = fleet_lock.lock_answer(output, task.state, task.exit_code)
            error += f": {task.error}" if error and task.error else ""
        self._drop_probe(held)
        held.next_ask = clock + fleet_lock.LOCK_POLL
        return locked, error

    def _drop_probe(self, held: Held) -> None:
        if held.probe is not None:
            swarm.remove_service(self.client, held.probe)
            held.probe = None


def busy_line(outcomes: list[RobotOutcome]) -> str:
    """The rollout's closing word on the robots left busy: who, and how to update them."""
    names = "; ".join(f"{o.robot} {o.reason}" for o in outcomes if o.verdict == fleet_lock.BUSY)
    return f"{names}; run the rollout again to update them, or with --force to update them unasked"
