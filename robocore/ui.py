"""Console output: one rich console on stderr for progress and messages."""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rich.console import Console


@functools.cache
def console() -> Console:
    """The console for human output (stderr, so stdout stays clean for --json)."""
    from rich.console import Console

    return Console(stderr=True, highlight=False)


@functools.cache
def stdout() -> Console:
    """The console for results meant for stdout (tables, JSON)."""
    from rich.console import Console

    return Console(highlight=False)
