"""bench/server_restart.py's rows: the ways of restarting a server it measures on each Fast DDS line."""

from __future__ import annotations

import json
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest
from bench_scripts import load


@pytest.fixture(scope="module")
def bench() -> ModuleType:
    return load("server_restart")


def test_kilted_restarts_robocores_server_without_a_hold_and_contrasts_the_2x_lease_and_a_fixed_guid(
        bench: ModuleType) -> None:
    robot = bench.robot_of("kilted")
    assert robot.fastdds_line == 3 and "-i" not in bench.fastdds.server_process(robot, 0).command
    rows = bench.rows_of(robot, 0)
    assert all(row["hold"] == 0 and not row["backup"] for row in rows.values())
    assert [row.get("fixed_id", False) for row in rows.values()] == [False, False, False, True]
    # robocore's own lease (row 1, 2) against 2.x's 8 s (row 3), the server's profile changed for it
    lease = bench.fastdds.server_liveliness(robot).lease_ms // 1000
    assert [label.split(", ")[1] for label in rows] == [f"lease {lease} s (robocore)"] * 2 + ["lease 8 s (2.x's)",
                                                                                              "no hold"]
    assert [row.get("liveliness") for row in rows.values()] == [None, None, bench.LEASE_8S, None]
    assert bench.LEASE_8S.lease_ms == 8000 and bench.LEASE_8S.hold_seconds == 0


def test_a_kilted_run_gets_a_result_file_of_its_own(bench: ModuleType, tmp_path: Path, monkeypatch: Any) -> None:
    """Kilted's figures go beside Jazzy's (``server_restart-kilted.json``), not over them."""
    monkeypatch.setenv("ROBOCORE_BENCH_RESULTS", str(tmp_path))
    assert bench.record("server_restart", [], variant="kilted").name == "server_restart-kilted.json"
    assert json.loads((tmp_path / "server_restart-kilted.json").read_text())["variant"] == "kilted"
    assert bench.record("server_restart", []).name == "server_restart.json"
    with pytest.raises(ValueError):
        bench.record("server_restart", [], variant="../x")


def test_jazzy_keeps_its_rows_with_robocores_hold(bench: ModuleType) -> None:
    robot = bench.robot_of("jazzy")
    rows = bench.rows_of(robot, bench.fastdds.restart_hold_seconds(robot))
    assert "same GUID, hold 12 s (robocore)" in rows
    assert sum(row["backup"] for row in rows.values()) == 2


def test_a_rows_median_is_judged_against_5_s_for_robocores_3x_rows_only(bench: ModuleType) -> None:
    kilted, jazzy = bench.robot_of("kilted"), bench.robot_of("jazzy")
    inf = float("inf")
    assert bench.seconds_of("HEARD 1.6 s after its start, 2.3 s after the stop (stop took 0.2 s)") == (1.6, 2.3)
    assert bench.seconds_of("NOTHING (stop took 0.1 s)") == (inf, inf)
    ours = bench.median_figure("new GUID, lease 3 s (robocore), SIGKILL stop", [(1.6, 2.4), (2.0, 2.6), (1.8, 2.5)],
                               kilted)
    assert (ours.value, ours.unit, ours.goal, ours.met) == (2.5, "s", "< 5 s", True)
    assert "from the listener's start 1.8 s" in ours.detail
    slow = bench.median_figure("new GUID, lease 3 s (robocore), SIGKILL stop", [(4.5, 5.5), (4.0, 7.0), (inf, inf)],
                               kilted)
    assert slow.value == 7.0 and slow.met is False and "1 never heard" in slow.detail
    never = bench.median_figure("same GUID, no hold", [(inf, inf)] * 3, jazzy)
    assert never.value == "NOTHING" and never.goal is None and never.met is None
    contrast = bench.median_figure("new GUID, lease 8 s (2.x's), SIGKILL stop", [(6.5, 7.0), (6.8, 7.4)], kilted)
    assert contrast.goal is None and contrast.met is None
