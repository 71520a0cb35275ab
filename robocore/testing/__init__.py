"""Test a robot project's running graph from pytest: ``pip install "robocore[testing]"``.

The plugin (:mod:`robocore.testing.plugin`, registered through the ``pytest11`` entry point) gives
tests the ``robot`` fixture: the project of the nearest robot.yaml (or ``--robocore-project DIR``),
built with its own caches and started isolated on the local Docker daemon, with ``robot.graph``, a
ROS 2 node of the test process in the robot's graph. ``docs/testing.md`` documents the API.

This package imports nothing heavy: pytest loads it in every session.
"""

from __future__ import annotations

from typing import Any

__all__ = ["BringUpError", "FaultError", "Faults", "Graph", "RobotUnderTest", "bring_up"]


def __getattr__(name: str) -> Any:
    """The public names, imported on first use."""
    if name in {"BringUpError", "RobotUnderTest", "bring_up"}:
        from robocore.testing import bringup

        return getattr(bringup, name)
    if name in {"FaultError", "Faults"}:
        from robocore.testing import faults

        return getattr(faults, name)
    if name == "Graph":
        from robocore.testing.graph import Graph

        return Graph
    raise AttributeError(name)
