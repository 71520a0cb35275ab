"""run and down: create, replace or remove each host's containers (issue #4)."""

from __future__ import annotations

from robocore.commands.context import Options
from robocore.errors import NotImplementedYet


def run(options: Options, *, host: str | None, tag: str | None) -> None:
    """(Re)start containers on hosts."""
    options.load()
    raise NotImplementedYet("run is not implemented yet")


def down(options: Options, *, host: str | None) -> None:
    """Stop and remove containers."""
    options.load()
    raise NotImplementedYet("down is not implemented yet")
