"""bench/server_restart.py's rows: the ways of restarting a server it measures on each Fast DDS line."""

from __future__ import annotations

from types import ModuleType

import pytest
from bench_scripts import load


@pytest.fixture(scope="module")
def bench() -> ModuleType:
    return load("server_restart")


def test_kilted_restarts_robocores_server_without_a_hold_and_contrasts_a_fixed_guid(bench: ModuleType) -> None:
    robot = bench.robot_of("kilted")
    assert robot.fastdds_line == 3 and "-i" not in bench.fastdds.server_process(robot, 0).command
    rows = bench.rows_of(robot, 0)
    assert all(row["hold"] == 0 and not row["backup"] for row in rows.values())
    assert [row.get("fixed_id", False) for row in rows.values()] == [False, False, True]


def test_jazzy_keeps_its_rows_with_robocores_hold(bench: ModuleType) -> None:
    robot = bench.robot_of("jazzy")
    rows = bench.rows_of(robot, bench.fastdds.restart_hold_seconds(robot))
    assert "same GUID, hold 12 s (robocore)" in rows
    assert sum(row["backup"] for row in rows.values()) == 2
