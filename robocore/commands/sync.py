"""sync: install trees and runtime files to each host, atomically (issue #4)."""

from __future__ import annotations

from robocore.commands.context import Options
from robocore.errors import NotImplementedYet


def sync(options: Options, *, host: str | None) -> None:
    """Copy install trees to hosts."""
    options.load()
    raise NotImplementedYet("sync is not implemented yet")
