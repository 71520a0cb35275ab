"""status, logs and connect: looking at (and into) the running robot (issue #4)."""

from __future__ import annotations

from robocore.commands.context import Options
from robocore.errors import NotImplementedYet


def status(options: Options) -> None:
    """Print the state of every component."""
    options.load()
    raise NotImplementedYet("status is not implemented yet")


def logs(options: Options, *, component: str | None, follow: bool, tail: int) -> None:
    """Print container logs."""
    options.load()
    raise NotImplementedYet("logs is not implemented yet")


def connect(options: Options, *, component: str, cmd: str | None) -> int:
    """Shell in a live container."""
    options.load()
    raise NotImplementedYet("connect is not implemented yet")
