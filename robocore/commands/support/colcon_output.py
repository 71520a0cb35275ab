"""What build and test read from colcon's console output while it runs (on this machine or on a robot host)."""

from __future__ import annotations

from collections.abc import Callable

from robocore.commands.support.reporting import Reporter
from robocore.plan import colcon


def colcon_listener(component: str, doing: str, done: str, events: list[colcon.PackageEvent], other: list[str],
                    update: Callable[[str, str], None], report: Reporter) -> Callable[[str], None]:
    """A reader of colcon's output lines: package events go to ``events`` and are shown (``<doing> <pkg>``
    in the progress line, ``<pkg> [<done> ]finished 2.1s`` as a message); other lines go to ``other``."""
    prefix = f"{done} " if done else ""

    def on_line(line: str) -> None:
        event = colcon.parse_event(line)
        if event is None:
            if line.strip():
                other.append(line)
            return
        events.append(event)
        if event.state == "started":
            update(component, f"{doing} {event.package}")
        else:
            secs = f" {event.seconds:.1f}s" if event.seconds is not None else ""
            report.info(f"{component}: {event.package} {prefix}{event.state}{secs}")

    return on_line
