"""The integration lanes' locks (integration/lanes.py): a quiet test's body runs while no other lane is in a test
phase, a waiting quiet test is not starved by lanes that take turns, and nested holds take nothing more."""

from __future__ import annotations

import multiprocessing
import sys
import time
from pathlib import Path
from typing import Any

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "integration"))
import lanes

FORK = multiprocessing.get_context("fork")


@pytest.fixture(autouse=True)
def private_locks(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(lanes, "LOCK", tmp_path / "quiet.lock")
    monkeypatch.setattr(lanes, "TURNSTILE", tmp_path / "turnstile.lock")
    monkeypatch.setattr(lanes, "MODULES_LOCK", tmp_path / "modules.lock")
    monkeypatch.setattr(lanes, "MACHINE_LOCK", tmp_path / "machine.lock")


def _phases(log: Path, until: float, delay: float) -> None:
    """A lane that takes turns with another: after ``delay``, phase after phase, each 200 ms, back to back."""
    time.sleep(delay)
    while time.monotonic() < until:
        with lanes.working():
            start = time.monotonic()
            time.sleep(0.2)
            with log.open("a") as out:
                out.write(f"{start} {time.monotonic()}\n")


def _spans(log: Path) -> list[tuple[float, float]]:
    return [(float(a), float(b)) for a, b in (line.split() for line in log.read_text().splitlines())]


def test_a_quiet_body_waits_for_lanes_that_take_turns_and_runs_alone(tmp_path: Path) -> None:
    until = time.monotonic() + 4.0
    # the second lane half a phase behind the first: one of them always holds the lock
    lanes_ = [FORK.Process(target=_phases, args=(tmp_path / f"lane{n}.log", until, 0.1 * n)) for n in (0, 1)]
    for proc in lanes_:
        proc.start()
    time.sleep(0.5)  # both lanes are taking turns, so the shared lock is never free
    with lanes.quiet():
        got = time.monotonic()
        time.sleep(0.5)
        left = time.monotonic()
    for proc in lanes_:
        proc.join(10)
    spans = _spans(tmp_path / "lane0.log") + _spans(tmp_path / "lane1.log")
    # starved, the quiet body would have run only once both lanes had stopped taking turns
    assert any(start > left for start, _ in spans), "the quiet test waited for the lanes to stop"
    overlapping = [(a, b) for a, b in spans if a < left and b > got]
    assert overlapping == [], f"a lane's phase ran during the quiet body: {overlapping}"


def _quiet_once(done: Path, go: Any) -> None:
    go.wait(10)
    with lanes.quiet():
        done.write_text(str(time.monotonic()))


def _nested_holder(log: Path, go: Any) -> None:
    with lanes.working():
        go.set()
        time.sleep(0.5)  # the quiet test is waiting now, holding the turnstile
        with lanes.working():  # a build inside the phase
            log.write_text("inner held\n")
        time.sleep(0.3)
        with log.open("a") as out:
            out.write(f"{time.monotonic()}\n")


def test_a_nested_hold_takes_nothing_more_and_lets_go_with_the_outer_one(tmp_path: Path) -> None:
    """A build inside a test phase, while a quiet test waits, holds no second flock (it would wait behind the
    quiet test, which waits for the first: a deadlock), and the quiet body runs once the outer hold ends."""
    done, log = tmp_path / "quiet-ran", tmp_path / "holder.log"
    go = FORK.Event()
    quiet = FORK.Process(target=_quiet_once, args=(done, go))
    holder = FORK.Process(target=_nested_holder, args=(log, go))
    quiet.start()
    holder.start()
    holder.join(10)
    stuck = holder.is_alive()
    if stuck:
        holder.kill()
    quiet.join(10)
    assert not stuck, "the nested hold waited behind the quiet test: a deadlock"
    inner, let_go = log.read_text().splitlines()
    assert inner == "inner held"
    assert float(done.read_text()) >= float(let_go), "the quiet body ran while a lane was in a phase"


def _quiet_with_untimed_stretches(log: Path, rounds: int) -> None:
    """A quiet body: ``rounds`` times an untimed stretch, then a timed one (logged)."""
    with lanes.quiet():
        for _ in range(rounds):
            with lanes.untimed():
                time.sleep(0.3)
            start = time.monotonic()
            time.sleep(0.2)
            with log.open("a") as out:
                out.write(f"{start} {time.monotonic()}\n")


def test_an_untimed_stretch_lets_other_lanes_work_and_the_timed_parts_run_alone(tmp_path: Path) -> None:
    until = time.monotonic() + 5.0
    lanes_ = [FORK.Process(target=_phases, args=(tmp_path / f"lane{n}.log", until, 0.1 * n)) for n in (0, 1)]
    for proc in lanes_:
        proc.start()
    time.sleep(0.5)
    before = lanes.alone_seconds()
    with lanes.quiet():
        first = (time.monotonic(), time.monotonic() + 0.4)
        time.sleep(0.4)
        with lanes.untimed():
            given = time.monotonic()
            time.sleep(1.0)
            taken = time.monotonic()
        second = (time.monotonic(), 0.0)
        time.sleep(0.4)
        second = (second[0], time.monotonic())
    held = lanes.alone_seconds() - before
    for proc in lanes_:
        proc.join(10)
    spans = _spans(tmp_path / "lane0.log") + _spans(tmp_path / "lane1.log")
    assert any(given <= start and stop <= taken + 0.3 for start, stop in spans), \
        f"no lane worked while the body gave the machine back: {spans}"
    for got, left in (first, second):
        overlapping = [(a, b) for a, b in spans if a < left and b > got]
        assert overlapping == [], f"a lane's phase ran during a timed stretch: {overlapping}"
    # alone: both timed stretches and the waits to take the machine back, never the untimed second
    assert 0.8 <= held < 0.8 + (second[0] - taken) + 0.5, (held, first, given, taken, second)


def test_two_quiet_bodies_giving_the_machine_back_never_wait_for_each_other_for_ever(tmp_path: Path) -> None:
    """Each waits at the turnstile holding nothing of the lock: neither can hold what the other waits for."""
    bodies = [FORK.Process(target=_quiet_with_untimed_stretches, args=(tmp_path / f"quiet{n}.log", 4)) for n in (0, 1)]
    for proc in bodies:
        proc.start()
    for proc in bodies:
        proc.join(20)
    stuck = [proc.is_alive() for proc in bodies]
    for proc in bodies:
        if proc.is_alive():
            proc.kill()
    assert stuck == [False, False], "two quiet bodies waited for each other"
    zero, one = _spans(tmp_path / "quiet0.log"), _spans(tmp_path / "quiet1.log")
    assert len(zero) == len(one) == 4
    overlapping = [(a, b) for a, b in zero for c, d in one if a < d and c < b]
    assert overlapping == [], f"two timed stretches ran at once: {overlapping}"


def _quiet_once_after(done: Path, go: Any) -> None:
    go.wait(10)
    with lanes.quiet():
        done.write_text(str(time.monotonic()))


def test_an_untimed_stretch_outside_a_quiet_body_changes_nothing(tmp_path: Path) -> None:
    """In a phase that holds the machine shared, an untimed stretch does not let a quiet test in; outside any
    phase it takes nothing and counts nothing."""
    before = lanes.alone_seconds()
    with lanes.untimed():
        pass
    assert lanes.alone_seconds() == before
    done = tmp_path / "quiet-ran"
    go = FORK.Event()
    quiet = FORK.Process(target=_quiet_once_after, args=(done, go))
    quiet.start()
    with lanes.working():
        go.set()
        with lanes.untimed():
            time.sleep(0.5)
            inside = not done.exists()
        time.sleep(0.2)
        let_go = time.monotonic()
    quiet.join(10)
    assert inside, "a quiet test ran during an untimed stretch of a shared phase"
    assert float(done.read_text()) >= let_go


def _module(module: str, timed: bool, log: Path, seconds: float) -> None:
    """A lane running ``module`` for ``seconds`` under :func:`lanes.hold_module`, logging when it ran."""
    fd = lanes.hold_module(module, timed)
    start = time.monotonic()
    time.sleep(seconds)
    with log.open("a") as out:
        out.write(f"{start} {time.monotonic()}\n")
    if fd is not None:
        lanes.let_go(fd)


def test_a_busy_module_and_modules_with_quiet_tests_never_run_side_by_side(tmp_path: Path) -> None:
    busy = next(iter(lanes.BUSY))
    timed = [FORK.Process(target=_module, args=(f"test_t{n}.py", True, tmp_path / f"t{n}.log", 0.6)) for n in (0, 1)]
    for proc in timed:
        proc.start()
    time.sleep(0.2)  # both timed modules are under way
    swarm = FORK.Process(target=_module, args=(busy, False, tmp_path / "busy.log", 0.6))
    plain = FORK.Process(target=_module, args=("test_plain.py", False, tmp_path / "plain.log", 0.3))
    swarm.start()
    plain.start()
    for proc in (*timed, swarm, plain):
        proc.join(10)
    (b_start, b_end), = _spans(tmp_path / "busy.log")
    both = _spans(tmp_path / "t0.log") + _spans(tmp_path / "t1.log")
    # the two timed modules ran side by side; the busy one waited for both to end
    assert max(start for start, _ in both) < min(end for _, end in both), both
    assert all(end <= b_start or start >= b_end for start, end in both), (both, (b_start, b_end))
    # a module with no quiet tests waited for nothing
    (p_start, _), = _spans(tmp_path / "plain.log")
    assert p_start < b_start, "a module with no quiet tests waited for the timed ones"


def test_a_lanes_domain_is_held_as_the_plugins_runs_hold_theirs(monkeypatch: pytest.MonkeyPatch) -> None:
    """A domain a lane hands out is held machine-wide, so that no pytest-plugin run (this lane's or another's) is
    handed it; a domain held elsewhere is skipped; a turn later the lane lets its own hold go and takes it again."""
    from robocore.testing import bringup, domains

    monkeypatch.setattr(lanes, "domain_ids", lambda: range(40, 43))
    monkeypatch.setattr(lanes, "_domain_holds", {})
    monkeypatch.setattr(lanes, "_domain_turn", iter([0, 1, 2, 3]))
    elsewhere = domains.hold_domain(41)
    assert elsewhere is not None
    try:
        first, second = lanes.new_domain(), lanes.new_domain()
        assert (first, second) == (40, 42)  # 41 is held by another run
        assert domains.hold_domain(40) is None and domains.hold_domain(42) is None
        monkeypatch.setattr(domains, "DOMAINS", range(40, 43))
        with pytest.raises(bringup.BringUpError):
            domains.reserve_domain()
        assert lanes.new_domain() == 40  # a turn later: its own hold let go of and taken again
    finally:
        elsewhere.close()
        for holder in lanes._domain_holds.values():
            holder.close()


def _alone_module(module: str, log: Path, seconds: float) -> None:
    fd = lanes.hold_alone(module)
    start = time.monotonic()
    time.sleep(seconds)
    with log.open("a") as out:
        out.write(f"{start} {time.monotonic()}\n")
    lanes.let_go(fd)


def test_a_module_that_runs_alone_waits_for_every_other_and_holds_them_off(tmp_path: Path) -> None:
    alone = next(iter(lanes.ALONE))
    first = FORK.Process(target=_alone_module, args=("test_plain.py", tmp_path / "a.log", 0.5))
    first.start()
    time.sleep(0.15)
    solo = FORK.Process(target=_alone_module, args=(alone, tmp_path / "solo.log", 0.5))
    solo.start()
    time.sleep(0.15)
    later = FORK.Process(target=_alone_module, args=("test_other.py", tmp_path / "b.log", 0.3))
    later.start()
    for proc in (first, solo, later):
        proc.join(10)
    (s_start, s_end), = _spans(tmp_path / "solo.log")
    others = _spans(tmp_path / "a.log") + _spans(tmp_path / "b.log")
    assert all(end <= s_start or start >= s_end for start, end in others), (others, (s_start, s_end))
    # negative control: two ordinary modules run side by side
    a = FORK.Process(target=_alone_module, args=("test_x.py", tmp_path / "x.log", 0.4))
    b = FORK.Process(target=_alone_module, args=("test_y.py", tmp_path / "y.log", 0.4))
    a.start()
    b.start()
    a.join(10)
    b.join(10)
    (x_start, x_end), = _spans(tmp_path / "x.log")
    (y_start, y_end), = _spans(tmp_path / "y.log")
    assert x_start < y_end and y_start < x_end
