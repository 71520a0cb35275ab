"""The integration session's time table (integration/ci_times.py): each phase's wait for another lane is counted
once per phase, so that a long tear-down spent waiting behind a quiet test shows as held back, not as work."""

from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "integration"))
import ci_times


def _report(when: str, duration: float, start: float, properties: list[tuple[str, Any]]) -> pytest.TestReport:
    return pytest.TestReport(nodeid="integration/test_x.py::test_a", location=("integration/test_x.py", 1, "test_a"),
                             keywords={}, outcome="passed", longrepr=None, when=when, duration=duration,
                             start=start, stop=start + duration, user_properties=list(properties))


def test_each_phase_counts_only_its_own_wait() -> None:
    """A test's user properties pile up over its phases (the call's report carries the set-up's too): each report
    adds only the wait of its own phase."""
    item = SimpleNamespace(user_properties=[])
    table = ci_times.CiTimes(config=None)  # type: ignore[arg-type]
    for when, duration, waited, start in (("setup", 3.0, 2.0, 0.0), ("call", 1.0, 0.5, 3.0),
                                          ("teardown", 31.0, 30.0, 4.0)):
        ci_times.held_back(item, when, waited)  # type: ignore[arg-type]
        table.pytest_runtest_logreport(_report(when, duration, start, item.user_properties))
    [row] = table.rows()
    assert (row["setup"], row["call"], row["teardown"]) == (3.0, 1.0, 31.0)
    assert row["held_back"] == 32.5  # 2 + 0.5 + 30, not the 2 + 2.5 + 32.5 of every property of every report
    assert row["tests"] == 1 and row["wall"] == 35.0


def test_a_report_without_a_wait_counts_nothing() -> None:
    assert ci_times.held_back_of(_report("teardown", 5.0, 0.0, [("something else", 9)])) == 0.0
    assert ci_times.held_back_of(_report("call", 5.0, 0.0, [(ci_times.HELD_BACK + "setup", 9)])) == 0.0


def test_the_time_held_alone_is_counted_once_from_the_calls_report() -> None:
    item = SimpleNamespace(user_properties=[])
    table = ci_times.CiTimes(config=None)  # type: ignore[arg-type]
    table.pytest_runtest_logreport(_report("setup", 1.0, 0.0, item.user_properties))
    ci_times.held_alone(item, 12.5)  # type: ignore[arg-type]
    table.pytest_runtest_logreport(_report("call", 20.0, 1.0, item.user_properties))
    table.pytest_runtest_logreport(_report("teardown", 1.0, 21.0, item.user_properties))  # carries it too
    [row] = table.rows()
    assert row["alone"] == 12.5
