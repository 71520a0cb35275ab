"""Fakes of docker-py's client and containers, the parts robocore reads, for unit tests without a daemon.

Each records what robocore asked of it, so a test asserts on calls, not on patched internals.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Any


class FakeContainer:
    """A container: its log, status, restart count; whether it was started or removed.

    ``logs(follow=True)`` streams the log's chunks; any other read shows one chunk more than the last (a log that
    grows while robocore polls it), and ``polls`` counts those reads.
    """

    def __init__(self, log: Sequence[str | bytes] = (), *, status: str = "running", restarts: int = 0,
                 attrs: dict[str, Any] | None = None) -> None:
        self.chunks = [c.encode() if isinstance(c, str) else c for c in log]
        self.polls = 0
        self.status = status
        self.attrs: dict[str, Any] = {"RestartCount": restarts, **(attrs or {})}
        self.started = False
        self.removed: bool | None = None  # the ``force`` of the removal

    def logs(self, *, follow: bool = False, **kwargs: Any) -> bytes | Iterator[bytes]:
        if follow:
            return iter(self.chunks)
        self.polls += 1
        return b"".join(self.chunks[: self.polls])

    def reload(self) -> None:
        pass

    def start(self) -> None:
        self.started = True

    def remove(self, force: bool = False) -> None:
        self.removed = force


class FakeContainers:
    """``client.containers``: what was created, with docker-py's keyword arguments."""

    def __init__(self) -> None:
        self.created: list[dict[str, Any]] = []

    def create(self, **kwargs: Any) -> FakeContainer:
        self.created.append(kwargs)
        return FakeContainer()


class FakeDocker:
    """A docker-py client: its containers, and whether robocore closed it."""

    def __init__(self) -> None:
        self.containers = FakeContainers()
        self.closed = False

    def close(self) -> None:
        self.closed = True
