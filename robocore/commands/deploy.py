"""sync, run, down, status, logs, connect, release, rollback, doctor (issue #4)."""

from __future__ import annotations

from robocore.commands.context import Options
from robocore.errors import NotImplementedYet


def _todo(options: Options, name: str) -> NotImplementedYet:
    options.load()
    return NotImplementedYet(f"{name} is not implemented yet")


def sync(options: Options, *, host: str | None) -> None:
    """Copy install trees to hosts."""
    raise _todo(options, "sync")


def run(options: Options, *, host: str | None, tag: str | None) -> None:
    """(Re)start containers on hosts."""
    raise _todo(options, "run")


def down(options: Options, *, host: str | None) -> None:
    """Stop and remove containers."""
    raise _todo(options, "down")


def status(options: Options) -> None:
    """Print the state of every component."""
    raise _todo(options, "status")


def logs(options: Options, *, component: str | None, follow: bool, tail: int) -> None:
    """Print container logs."""
    raise _todo(options, "logs")


def connect(options: Options, *, component: str, cmd: str | None) -> int:
    """Shell in a live container."""
    raise _todo(options, "connect")


def release(options: Options, *, tag: str | None) -> None:
    """Tag and push images."""
    raise _todo(options, "release")


def rollback(options: Options, *, host: str | None) -> None:
    """Return hosts to their previous version."""
    raise _todo(options, "rollback")


def doctor(options: Options, *, host: str | None) -> None:
    """Check hosts."""
    raise _todo(options, "doctor")
