"""doctor: check every host and say what to fix (issue #4)."""

from __future__ import annotations

from robocore.commands.context import Options
from robocore.errors import NotImplementedYet


def doctor(options: Options, *, host: str | None) -> None:
    """Check hosts."""
    options.load()
    raise NotImplementedYet("doctor is not implemented yet")
