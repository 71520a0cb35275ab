"""release and rollback: versioned images in a registry (issue #4)."""

from __future__ import annotations

from robocore.commands.context import Options
from robocore.errors import NotImplementedYet


def release(options: Options, *, tag: str | None) -> None:
    """Tag and push images."""
    options.load()
    raise NotImplementedYet("release is not implemented yet")


def rollback(options: Options, *, host: str | None) -> None:
    """Return hosts to their previous version."""
    options.load()
    raise NotImplementedYet("rollback is not implemented yet")
