"""Where the integration session's minutes go: a table per test module, printed at the end of every run.

For each module: its tests, the seconds spent in set-up, in the tests themselves and in tear-down (summed over its
tests, as pytest's ``--durations`` counts them), how many of those seconds its phases were held back (waiting for
another lane's quiet test, or for the arm64 project's lock: :func:`held_back`; pytest counts that wait in the
phase, so a module run beside a quiet test shows a long tear-down that costs nothing alone), how many seconds its
quiet tests held the machine alone (every other lane standing still: :func:`held_alone`), its wall time (from
its first test's start to its last test's end, which includes waiting on a shared fixture another module made), the
lane (xdist worker) that ran it, and the machine's busy CPU over that wall time (all cores, from ``/proc/stat``: the
other lane's work and the background image run count too). The last line is the whole session: its wall time, its
busy CPU, and that CPU over the cores, the floor no ordering of the same work could beat.

With ``ROBOCORE_CI_TIMES=FILE`` the same table is written to FILE as JSON (``bench/ci.py`` records it in the bench
results). Under pytest-xdist the table is made by the controller, from the reports the workers send; a worker
prints nothing.
"""

from __future__ import annotations

import json
import os
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import pytest

#: Seconds between two readings of /proc/stat.
SAMPLE_EVERY = 1.0
#: The name of a test's user property that holds the seconds a phase waited before it ran (``HELD_BACK + when``).
HELD_BACK = "held back in "


def held_back(item: pytest.Item, when: str, seconds: float) -> None:
    """Record that phase ``when`` (setup, call, teardown) of ``item`` waited ``seconds`` for the machine before it
    ran: the phase's report carries it (as a user property, which pytest-xdist sends to the controller)."""
    item.user_properties.append((HELD_BACK + when, round(seconds, 3)))


#: The name of a test's user property that holds the seconds its body held the machine alone (a quiet test).
HELD_ALONE = "held the machine alone"


def held_alone(item: pytest.Item, seconds: float) -> None:
    """Record that the body of ``item`` held the machine alone for ``seconds`` (every other lane stood still)."""
    if seconds > 0:
        item.user_properties.append((HELD_ALONE, round(seconds, 3)))


def held_alone_of(report: pytest.TestReport) -> float:
    """The seconds the body of ``report``'s test held the machine alone (counted on the call's report only)."""
    if report.when != "call":
        return 0.0
    return sum(float(value) for name, value in report.user_properties if name == HELD_ALONE)


def held_back_of(report: pytest.TestReport) -> float:
    """The seconds the phase of ``report`` waited before it ran (0 when it did not say)."""
    key = HELD_BACK + report.when if report.when else ""
    return sum(float(value) for name, value in report.user_properties if name == key)


def busy_jiffies() -> tuple[int, int] | None:
    """The machine's CPU time so far from /proc/stat's first line, in clock ticks: (busy, busy + idle), or None
    where there is no /proc/stat."""
    try:
        with open("/proc/stat", encoding="ascii") as stat:
            fields = [int(v) for v in stat.readline().split()[1:8]]
    except (OSError, ValueError):
        return None
    user, nice, system, idle, iowait, irq, softirq = fields
    busy = user + nice + system + irq + softirq
    return busy, busy + idle + iowait


class CpuClock:
    """Samples the machine's busy CPU every :data:`SAMPLE_EVERY` seconds in a daemon thread, so that the busy
    CPU-seconds between any two moments of the session can be looked up afterwards."""

    def __init__(self) -> None:
        self.samples: list[tuple[float, int]] = []
        self.tick = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="ci-times-cpu", daemon=True)

    def start(self) -> None:
        """Take a first sample and go on sampling in the background."""
        self._sample()
        self._thread.start()

    def stop(self) -> None:
        """Take a last sample and stop sampling."""
        self._stop.set()
        self._sample()

    def _sample(self) -> None:
        reading = busy_jiffies()
        if reading is not None:
            self.samples.append((time.time(), reading[0]))

    def _run(self) -> None:
        while not self._stop.wait(SAMPLE_EVERY):
            self._sample()

    def busy_between(self, start: float, stop: float) -> float | None:
        """Busy CPU-seconds of the whole machine from ``start`` to ``stop`` (epoch seconds), from the nearest
        samples; None when the samples do not cover that span."""
        before = [s for s in self.samples if s[0] <= start + SAMPLE_EVERY]
        after = [s for s in self.samples if s[0] >= stop - SAMPLE_EVERY]
        if not before or not after:
            return None
        return max(0, after[0][1] - before[-1][1]) / self.tick


@dataclass
class ModuleTimes:
    """What one test module cost."""

    module: str
    tests: int = 0
    setup: float = 0.0
    call: float = 0.0
    teardown: float = 0.0
    held_back: float = 0.0  # of setup + call + teardown: waiting for another lane (a quiet test, a project's lock)
    alone: float = 0.0  # of call: the machine held alone (every other lane standing still)
    first_start: float = 0.0
    last_stop: float = 0.0
    lanes: set[str] = field(default_factory=set)
    failed: int = 0

    @property
    def wall(self) -> float:
        """Seconds from the module's first test's start to its last test's end."""
        return max(0.0, self.last_stop - self.first_start)


def lane_of(report: pytest.TestReport) -> str:
    """The xdist worker (``gw0``, ``gw1``) that sent ``report``, or ``main`` in a session without workers."""
    gateway = getattr(getattr(report, "node", None), "gateway", None)
    return str(getattr(gateway, "id", "main"))


class CiTimes:
    """The plugin: collects every test report's phases by module, prints the table at the end."""

    def __init__(self, config: pytest.Config) -> None:
        self.config = config
        self.modules: dict[str, ModuleTimes] = {}
        self.clock = CpuClock()
        self.started = time.time()
        self.cores = os.cpu_count() or 1

    def pytest_sessionstart(self) -> None:
        self.started = time.time()
        self.clock.start()

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        module = report.nodeid.split("::", 1)[0]
        times = self.modules.setdefault(module, ModuleTimes(module, first_start=report.start))
        setattr(times, report.when, getattr(times, report.when) + report.duration)
        times.held_back += held_back_of(report)
        times.alone += held_alone_of(report)
        times.first_start = min(times.first_start, report.start)
        times.last_stop = max(times.last_stop, report.stop)
        times.lanes.add(lane_of(report))
        if report.when == "call":
            times.tests += 1
        if report.failed:
            times.failed += 1

    def rows(self) -> list[dict[str, Any]]:
        """The table's rows, slowest wall time first."""
        out = []
        for times in sorted(self.modules.values(), key=lambda t: -t.wall):
            busy = self.clock.busy_between(times.first_start, times.last_stop)
            row = asdict(times)
            row.update(lanes=sorted(times.lanes), wall=round(times.wall, 1), busy_cpu=busy and round(busy, 1),
                       setup=round(times.setup, 1), call=round(times.call, 1), teardown=round(times.teardown, 1),
                       held_back=round(times.held_back, 1), alone=round(times.alone, 1),
                       first_start=round(times.first_start - self.started, 1),
                       last_stop=round(times.last_stop - self.started, 1))
            out.append(row)
        return out

    def pytest_terminal_summary(self, terminalreporter: Any) -> None:
        self.clock.stop()
        rows = self.rows()
        wall = time.time() - self.started
        busy = self.clock.busy_between(self.started, time.time())
        write = terminalreporter.write_line
        terminalreporter.section("where the minutes went (per module)")
        write(f"{'module':<44} {'lane':<7} {'tests':>5} {'set-up':>7} {'tests':>7} {'tear':>6} {'held':>6} "
              f"{'alone':>6} {'from':>6} {'wall':>7} {'busy CPU':>9}")
        for row in rows:
            cpu = "-" if row["busy_cpu"] is None else f"{row['busy_cpu']:.0f} s"
            write(f"{row['module']:<44} {','.join(row['lanes']):<7} {row['tests']:>5} {row['setup']:>7.1f} "
                  f"{row['call']:>7.1f} {row['teardown']:>6.1f} {row['held_back']:>6.1f} {row['alone']:>6.1f} "
                  f"{row['first_start']:>6.0f} {row['wall']:>7.1f} {cpu:>9}")
        floor = "" if busy is None else f", busy CPU {busy:.0f} s: {busy / self.cores:.0f} s on {self.cores} cores"
        write(f"session: {wall:.0f} s wall{floor}")
        target = os.environ.get("ROBOCORE_CI_TIMES")
        if target:
            Path(target).write_text(json.dumps({"wall": round(wall, 1), "busy_cpu": busy and round(busy, 1),
                                                "cores": self.cores, "modules": rows}, indent=2) + "\n")


def register(config: pytest.Config) -> None:
    """Registers the table's plugin in the controller (or a session without workers), not in an xdist worker."""
    if not hasattr(config, "workerinput"):
        config.pluginmanager.register(CiTimes(config), "robocore-ci-times")
