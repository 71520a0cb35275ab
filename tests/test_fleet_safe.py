"""Updates only at a safe moment, against a fake swarm: a robot that holds its update lock, or whose maintenance
window is closed, is held back while the others of its wave are changed and gated; it is changed as soon as it is
free; past ``rollout.timeouts.busy`` it is left as it was and reported ``busy``; ``--force`` asks nothing.

No Docker: the swarm adapter's calls are replaced by a swarm whose robot nodes are ready, whose new tasks run at
once, and whose lock probes end at once with the robot's lock as their answer; the clock is a fake one advanced
by the gate's own sleeps, and the maintenance windows' clock is a fixed moment.
"""

from __future__ import annotations

import json
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import fleet_world
import pytest
from fleet_world import Clock

from robocore.adapters import swarm
from robocore.commands import fleet_gate, fleet_rollout, fleet_safe
from robocore.commands.fleet_gate import HEALTHY, PENDING, Change, Gate
from robocore.commands.fleet_rollout import RobotOutcome
from robocore.commands.fleet_safe import Asker, busy_line
from robocore.commands.fleet_swarm import FleetProject, robot_nodes
from robocore.commands.support.context import Options
from robocore.plan import fleet_lock
from robocore.plan import swarm_services as plan

FLEET = """\
manager: {ip: 10.0.0.2}
registry: 10.0.0.2:5000
robots:
  - {name: r1, hosts: {main: {ip: 10.1.1.1}}}
  - {name: r2, labels: {site: field}, hosts: {main: {ip: 10.1.2.1}}}
  - {name: r3, hosts: {main: {ip: 10.1.3.1}}}
rollout:
  health: {running: 2}
  timeouts: {robot: 1000, wave: 30, busy: 60}
"""
DIGEST = "@sha256:" + "a" * 64
RELEASE = plan.Release(version="v2", components={"talker": {"amd64": "10.0.0.2:5000/p-talker" + DIGEST}},
                       base={"amd64": "10.0.0.2:5000/p-base" + DIGEST})
#: A Monday afternoon, UTC: the maintenance windows' fixed clock.
MONDAY = datetime(2026, 12, 7, 15, 0, tzinfo=timezone.utc)


class FakeSwarm:
    """The robots' nodes (all ready unless ``down``), their locks, every service made, every lock probe asked, and
    the labels set."""

    def __init__(self, project: str, robots: list[str]) -> None:
        self.locked = dict.fromkeys(robots, False)
        self.down: set[str] = set()
        self.asked: list[str] = []  # the robot of each lock probe, in order
        self.applied: list[str] = []  # every service created or updated
        self.labels: dict[str, dict[str, str]] = {}  # service -> labels set on it
        self.live: set[str] = set()  # lock probe services not removed
        self.project = project
        self.robots = robots
        self.silent = False  # no probe output reaches the manager (a node whose logs it cannot stream)

    def nodes(self, _client: Any) -> list[swarm.NodeInfo]:
        return [swarm.NodeInfo(id=f"n{r}", hostname=r, labels=plan.node_labels(self.project, r, "main", "amd64"),
                               state="down" if r in self.down else "ready", availability="active", addr="")
                for r in self.robots]

    def robot_of(self, service: str) -> str:
        return next(r for r in self.robots if f"-{r}-" in service)

    def tasks(self, _client: Any, service: str) -> list[swarm.TaskInfo]:
        if "-probe-lock-" in service:  # it exits 0 when free, 1 when locked
            locked = self.locked[self.robot_of(service)]
            return [swarm.TaskInfo(id="tp", node_id="n", state="failed" if locked else "complete", desired="shutdown",
                                   image="", created="1", error="", exit_code=int(locked), container="c")]
        if service not in self.applied:
            return []
        image = RELEASE.components["talker"]["amd64"] if "talker" in service else RELEASE.base["amd64"]
        return [swarm.TaskInfo(id=f"t-{service}", node_id="n", state="running", desired="running", image=image,
                               created="1", error="", exit_code=None, container="c")]

    def apply_service(self, _client: Any, spec: plan.ServiceSpec, _ids: Any) -> str:
        if "-probe-lock-" in spec.name:
            assert spec.args is not None and "--topic" in spec.args and fleet_lock.LOCK_TOPIC in spec.args
            self.asked.append(spec.robot)
            self.live.add(spec.name)
        else:
            self.applied.append(spec.name)
        return spec.name

    def service_logs(self, _client: Any, service: str) -> str:
        if self.silent:
            return ""
        locked = self.locked[self.robot_of(service)]
        return f"task@node | {json.dumps({'locked': locked, 'publishers': 1, 'heard': 1, 'error': ''})}\n"

    def services(self, _client: Any, _label: str) -> list[swarm.ServiceInfo]:
        return [swarm.ServiceInfo(id=r, name=f"{self.project}-{r}-talker", image="", version=1, attrs={},
                                  labels={plan.LABEL_ROBOT: r}) for r in self.robots]

    def set_labels(self, _client: Any, name: str, labels: dict[str, str]) -> None:
        self.labels.setdefault(name, {}).update(labels)


@pytest.fixture
def world(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[FleetProject, Clock, FakeSwarm]:
    fleet_project = fleet_world.fleet_project(tmp_path / "p", FLEET)
    clock = Clock()
    fake = FakeSwarm(fleet_project.project.name, fleet_project.fleet.robot_names)
    monkeypatch.setattr(fleet_rollout, "time", clock)
    monkeypatch.setattr(fleet_gate, "time", clock)
    monkeypatch.setattr(fleet_safe, "time", clock)
    for name in ("nodes", "tasks", "apply_service", "service_logs", "services", "set_labels"):
        monkeypatch.setattr(swarm, name, getattr(fake, name))
    monkeypatch.setattr(swarm, "ensure_configs", lambda _client, _configs: {})
    monkeypatch.setattr(swarm, "updating", lambda _client, _name: False)
    monkeypatch.setattr(swarm, "remove_service", lambda _client, name: fake.live.discard(name))
    return fleet_project, clock, fake


def wave(world: Any, *, force: bool = False, fleet_text: str | None = None,
         release_after: dict[str, float] | None = None,
         quiet: bool = True) -> tuple[list[Change], Asker, Options, dict[str, float]]:
    """Run one wave of r1, r2, r3 (each changed robot's services made in the fake swarm, then gated), each robot of
    ``release_after`` releasing its lock that many seconds after the wave's start; when each robot's change
    started (seconds after the wave's start)."""
    fleet_project, clock, fake = world
    if fleet_text is not None:
        fleet_project = fleet_world.fleet_project(fleet_project.project.root, fleet_text)
    options = Options(project_dir=fleet_project.project.root, quiet=quiet)
    began = clock.now
    started: dict[str, float] = {}
    release_after = release_after or {}

    def start(robot: str, *, health: str) -> Change:
        for name, after in release_after.items():
            if clock.now - began >= after:
                fake.locked[name] = False
        specs = plan.robot_services(fleet_project.project, robot, fleet_project.instances[robot], RELEASE)
        for spec in specs:
            fake.applied.append(spec.name)
        started[robot] = clock.now - began
        return Change(robot=robot, wave="rest", release="v2", specs=specs, before={s.name: set() for s in specs},
                      started=clock.now, deadline=clock.now + 1000, verdict=PENDING if health else None)

    original_step = Asker.step

    def step(self: Asker, by_robot: Any) -> list[Change]:  # the locks released on time, whoever looks
        for name, after in release_after.items():
            if clock.now - began >= after:
                fake.locked[name] = False
        return original_step(self, by_robot)

    gate = Gate(object(), fleet_project, RELEASE, {"v2": RELEASE}, options)  # type: ignore[arg-type]
    pytest.MonkeyPatch().setattr(Asker, "step", step)
    try:
        with Asker(object(), fleet_project, "rest", RELEASE, start, options.report,  # type: ignore[arg-type]
                   force=force, clock=lambda: MONDAY) as asker:
            changes = asker.first(("r1", "r2", "r3"), robot_nodes(fake.nodes(None), fleet_project))
            gate.run(changes, clock.now + fleet_project.fleet.rollout.timeouts.wave, asker)
    finally:
        Asker.step = original_step  # type: ignore[method-assign]
    return changes, asker, options, started


def test_a_locked_robot_is_held_while_the_others_go_and_changed_once_free(world: Any) -> None:
    _, _, fake = world
    fake.locked["r2"] = True
    changes, asker, _, started = wave(world, release_after={"r2": 20})
    assert {c.robot: c.verdict for c in changes} == {"r1": HEALTHY, "r3": HEALTHY, "r2": HEALTHY}
    assert started["r1"] < 2 and started["r3"] < 2  # the others did not wait for r2
    assert 20 <= started["r2"] < 20 + fleet_lock.LOCK_POLL + 1  # changed within a poll of its release
    assert fake.asked.count("r2") > 5 and fake.asked.count("r1") == 1  # asked again until free; r1 once
    r2 = next(c for c in changes if c.robot == "r2")
    assert r2.waited >= 20  # the wave's time does not count its wait (30 s wave, r2 started after 20 s)
    label = fake.labels[f"{world[0].name}-r2-talker"]
    assert label[fleet_lock.LABEL_BUSY].endswith("Z") and label[plan.LABEL_REASON] == \
        "holds its update lock (/robocore/update_lock)"  # fleet status: busy since, and why
    assert not asker.given_up and not fake.live  # every lock probe removed
    assert f"{world[0].name}-r1-talker" not in fake.labels


def test_when_no_output_reaches_the_manager_the_exit_code_answers(world: Any) -> None:
    """Seen on a robot that had reconnected: the manager could not stream its node's logs. The probe's exit code
    (0 free, 1 locked) then answers, after the wait for its output."""
    _, _, fake = world
    fake.locked["r2"], fake.silent = True, True
    changes, asker, _, started = wave(world, release_after={"r2": 20})
    assert {c.robot: c.verdict for c in changes} == dict.fromkeys(("r1", "r3", "r2"), HEALTHY)
    assert max(started["r1"], started["r3"]) < fleet_safe.ANSWER_WAIT + 2 <= 20 <= started["r2"]
    assert not asker.given_up
    assert fleet_lock.lock_answer("", "complete", 0) == (False, "")
    assert fleet_lock.lock_answer("", "failed", 1) == (True, "")
    assert fleet_lock.lock_answer("", "failed", 2) == (None, "the update-lock probe printed no answer (failed)")


def test_without_a_lock_every_robot_is_changed_at_once(world: Any) -> None:
    """The negative control: the same wave, nobody holding a lock."""
    changes, _, _, started = wave(world)
    assert {c.robot: c.verdict for c in changes} == dict.fromkeys(("r1", "r2", "r3"), HEALTHY)
    assert max(started.values()) < 2 and not world[2].labels


def test_past_timeouts_busy_a_robot_is_left_as_it_was_and_reported_busy(world: Any) -> None:
    project, _, fake = world
    fake.locked["r2"] = True
    changes, asker, _, _ = wave(world)
    assert {c.robot for c in changes} == {"r1", "r3"}
    assert f"{project.name}-r2-talker" not in fake.applied  # never touched
    outcomes = asker.outcomes(RobotOutcome)
    assert [(o.robot, o.verdict) for o in outcomes] == [("r2", "busy")]
    assert 60 <= outcomes[0].seconds < 62
    assert outcomes[0].reason == ("not updated to v2: holds its update lock (/robocore/update_lock) for more than "
                                  "60 s (rollout.timeouts.busy)")
    labels = fake.labels[f"{project.name}-r2-talker"]
    assert (labels[fleet_lock.LABEL_BUSY], labels[plan.LABEL_HEALTH]) == ("", "busy")
    assert busy_line(outcomes).startswith("r2 not updated to v2: holds its update lock")
    assert not fake.live


def test_a_held_robot_is_said_held_every_10_s_with_its_bound(world: Any, capsys: pytest.CaptureFixture[str]) -> None:
    """A rollout is never long silent: r2, held by its lock for the whole 60 s of timeouts.busy, is said held about
    every 10 s, with how long of that bound has gone; the robots changed at once are not said held."""
    _, _, fake = world
    fake.locked["r2"] = True
    wave(world, quiet=False)
    lines = [line for line in capsys.readouterr().err.splitlines() if "deferred" in line]
    assert lines[0] == "  r2: deferred: holds its update lock (/robocore/update_lock)", lines
    again = lines[1:]
    assert 4 <= len(again) <= 6 and all(line.startswith("  r2: still deferred: holds its update lock") and
                                        line.endswith(" of 60 s, timeouts.busy)") for line in again), lines
    assert again[0].endswith("(10 s of 60 s, timeouts.busy)"), again


def test_a_closed_window_holds_a_robot_without_asking_it(world: Any) -> None:
    text = FLEET + '  windows:\n    - {labels: {site: field}, from: "22:00", to: "06:00", timezone: Europe/Berlin}\n'
    changes, asker, _, _ = wave(world, fleet_text=text)
    assert {c.robot for c in changes} == {"r1", "r3"}
    assert "r2" not in world[2].asked  # its window is closed: its lock is not asked
    (outcome,) = asker.outcomes(RobotOutcome)
    assert outcome.reason == ("not updated to v2: outside its maintenance window: window opens at 2026-12-07 22:00 "
                              "Europe/Berlin for more than 60 s (rollout.timeouts.busy)")


def test_an_open_window_lets_the_robot_be_asked(world: Any) -> None:
    text = FLEET + '  windows:\n    - {labels: {site: field}, from: "15:00", to: "17:00", timezone: UTC}\n'
    changes, _, _, _ = wave(world, fleet_text=text)
    assert {c.robot for c in changes} == {"r1", "r2", "r3"} and "r2" in world[2].asked


def test_force_asks_nothing_and_says_so(world: Any, capsys: pytest.CaptureFixture[str]) -> None:
    _, _, fake = world
    fake.locked["r2"] = True
    text = FLEET + '  windows:\n    - {robots: [r3], from: "01:00", to: "02:00"}\n'
    changes, asker, _, started = wave(world, force=True, fleet_text=text)
    assert {c.robot: c.verdict for c in changes} == dict.fromkeys(("r1", "r2", "r3"), HEALTHY)
    assert not fake.asked and not asker.given_up and max(started.values()) < 1
    assert "--force: wave rest updated without asking its robots' update lock or maintenance window" in \
        capsys.readouterr().err


def test_an_offline_robot_is_not_asked_but_pending(world: Any) -> None:
    _, _, fake = world
    fake.down.add("r3")
    changes, _, _, _ = wave(world)
    assert {c.robot: c.verdict for c in changes}["r3"] == PENDING and "r3" not in fake.asked


def test_a_lock_that_cannot_be_read_holds_the_robot(world: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    _, _, fake = world
    monkeypatch.setattr(swarm, "service_logs", lambda _c, s: '{"locked": null, "error": "cannot subscribe"}' if
                        "-r2-" in s else fake.service_logs(_c, s))
    _, asker, _, _ = wave(world)
    (outcome,) = asker.outcomes(RobotOutcome)
    assert "cannot read its update lock (cannot subscribe)" in outcome.reason


def test_the_lock_probe_and_its_answer() -> None:
    made = fleet_world.fleet_project(Path("/p"), FLEET)
    spec = fleet_lock.lock_probe_service(made.project, "r1", made.instances["r1"], RELEASE, "print(1)", "ab")
    assert spec.args == ("python3", plan.PROBE_SCRIPT, "--topic", "/robocore/update_lock", "--wait", "5")
    assert spec.restart == "none" and spec.image == RELEASE.base["amd64"] and "-probe-lock-ab" in spec.name
    assert plan.LABEL_PROBE in spec.label_map  # not a robot's service: fleet status leaves it out
    assert fleet_lock.lock_answer('x | {"locked": true, "error": ""}') == (True, "")
    assert fleet_lock.lock_answer('{"locked": false}') == (False, "")
    assert fleet_lock.lock_answer("") == (None, "the update-lock probe printed no answer")
    assert fleet_lock.lock_answer('{"locked": null, "error": "no std_msgs"}') == (None, "no std_msgs")
    assert fleet_lock.lock_resource(made.instances["r1"]) == "fleet-lock-probe"


# --- the ROS 1 lock probe against a stand-in master ----------------------------------------------------------------


def lock_probe_ros1(tmp_path: Path, master: str) -> tuple[int, dict[str, object]]:
    """The ROS 1 lock probe run as its service runs it; its exit code and answer."""
    import os
    import subprocess
    import sys

    from robocore import resources

    script = tmp_path / "fleet-lock-probe.py"
    script.write_bytes(resources.read("fleet-lock-probe-ros1"))
    done = subprocess.run([sys.executable, str(script), "--topic", fleet_lock.LOCK_TOPIC, "--wait", "5"],
                          capture_output=True, text=True, timeout=60, env={**os.environ, "ROS_MASTER_URI": master},
                          check=False)
    lines = done.stdout.strip().splitlines()
    assert lines, done.stderr
    return done.returncode, json.loads(lines[-1])


def test_the_ros1_lock_probe_asks_the_master_first(tmp_path: Path) -> None:
    from test_fleet_ros1 import serving

    state: list[Any] = [[["/rosout", ["/talker"]]], [], []]
    with serving({"getSystemState": lambda caller: [1, "", state]}) as master:
        assert lock_probe_ros1(tmp_path, master) == (0, {"locked": False, "publishers": 0, "heard": 0, "error": ""})
        state[0].append([fleet_lock.LOCK_TOPIC, ["/mission"]])  # a publisher: it must be heard, with rospy
        code, answer = lock_probe_ros1(tmp_path, master)
    # no rospy on this machine: it cannot tell (exit 2), and a robot that cannot be asked is held (hold_reason)
    assert code == 2 and answer["locked"] is None and "cannot subscribe" in str(answer["error"]), answer
    assert fleet_lock.lock_answer(json.dumps(answer))[0] is None
    with serving({}) as gone:
        pass  # no master answers: no node runs, none holds a lock
    assert lock_probe_ros1(tmp_path, gone)[1]["locked"] is False


def test_force_is_the_rollouts_flag_only(tmp_path: Path) -> None:
    from robocore.commands.fleet import fleet
    from robocore.errors import UsageError

    with pytest.raises(UsageError, match="--force is fleet rollout's, not fleet status's"):
        fleet(Options(project_dir=tmp_path), verb="status", version=None, robots=[], force=True)
