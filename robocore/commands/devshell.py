"""shell: a dev container in a component's environment (issue #5)."""

from __future__ import annotations

from robocore.commands.context import Options
from robocore.errors import NotImplementedYet


def run(options: Options, *, component: str, cmd: str | None, new: bool, devices: str | None,
        gpus: bool | None, privileged: bool) -> int:
    """Open (or join) the dev container of ``component``."""
    options.load()
    raise NotImplementedYet("shell is not implemented yet")
