"""The error of robocore's test fixtures: a robot that could not be brought up."""

from __future__ import annotations

from robocore.errors import RobocoreError


class BringUpError(RobocoreError):
    """The robot could not be brought up for tests (build, Docker, a component dying at start)."""

    exit_code = 6
