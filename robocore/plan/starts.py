"""Containers' start times as Docker reports them, and which containers started before their discovery servers.

Pure and light (no configuration model): ``run`` uses it to restart the nodes a ROS master does not know, and
``status`` to say which they are, also on its fast path (:mod:`robocore.commands.support.status_memo`).
"""

from __future__ import annotations

import re
from collections.abc import Collection, Iterable, Mapping
from datetime import datetime, timezone

_FRACTION = re.compile(r"\.(\d+)")


def docker_time(text: str) -> datetime | None:
    """A Docker timestamp (RFC 3339, up to nanoseconds, ``Z``) as an aware datetime; None when empty or unreadable
    (Docker's ``0001-01-01T00:00:00Z`` of a container that never started is read as it is)."""
    micro = _FRACTION.sub(lambda m: "." + (m[1] + "000000")[:6], text.strip(), count=1)
    try:
        stamp = datetime.fromisoformat(micro.replace("Z", "+00:00"))
    except ValueError:
        return None
    return stamp if stamp.tzinfo is not None else stamp.replace(tzinfo=timezone.utc)


def docker_epoch(text: str) -> float:
    """A Docker timestamp as seconds since the epoch (to the microsecond), for timing what Docker recorded (a
    container's start, a log line) against other such times; ValueError when it cannot be read."""
    stamp = docker_time(text)
    if stamp is None:
        raise ValueError(f"not a Docker timestamp: {text!r}")
    return stamp.timestamp()


def latest_start(times: Iterable[str]) -> datetime | None:
    """The latest of Docker start times ``times`` that can be read, None when there is none."""
    known = [t for t in map(docker_time, times) if t is not None]
    return max(known) if known else None


def started_before_servers(started: Mapping[str, str], servers: Collection[str],
                           elsewhere: datetime | None = None) -> set[str]:
    """The containers of ``started`` (name -> Docker start time, "" when not running) that started before the
    last start of the running ``servers`` among them, or of a server ``elsewhere`` (another host): a server
    whose nodes register only when they start does not know them."""
    last = latest_start([started[name] for name in servers if started.get(name)])
    starts = [t for t in (last, elsewhere) if t is not None]
    if not starts:
        return set()
    newest = max(starts)
    return {name for name, text in started.items() if name not in servers and text
            and (when := docker_time(text)) is not None and when < newest}
