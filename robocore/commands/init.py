"""init: a new robot project from the copier template."""

from __future__ import annotations

from pathlib import Path

from robocore.errors import NotImplementedYet


def run(path: Path, *, defaults: bool, distro: str | None, base: str | None, dry_run: bool) -> None:
    """Render the template into ``path``."""
    raise NotImplementedYet("init is not implemented yet")
