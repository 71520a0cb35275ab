"""How the integration suites share one machine: lanes, one queue, and quiet tests.

The integration session runs on pytest-xdist workers (``-n LANES --dist loadgroup --no-loadscope-reorder``, in the
noxfile), each a *lane*: when a lane has finished its group of modules it takes the next group from one queue, in
:data:`QUEUE`'s order. A suite spends much of its time waiting (a gate, a rollout, a fault's window, a download),
and the other lane works meanwhile.

- :data:`QUEUE`: groups of modules, the longest first so that the lanes end together; the modules of one group
  run one after the other in one lane because they share a project name and its images, containers or hosts.
  A module not named here is a group of its own, handed out before the last groups (:data:`LAST`: they need the
  arm64 images, made in the background meanwhile).
- Quiet tests (``@pytest.mark.quiet``) time what they prove (a node heard again within 2 s, a server's hold, no gap
  over 1.2 s): while one runs, no other lane builds (:func:`quiet`, :func:`heavy`), as on the quiet machine their
  bounds were set on. A build waits for a quiet test, a quiet test for the builds under way; the rest runs freely.
- Each lane draws ROS domain IDs and ports from a range of its own (:func:`domain_ids`, :func:`ports`), so that two
  lanes never pick the same one at the same moment.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

#: Groups of modules in the order the lanes take them. A module not listed is a group of its own, handed out
#: after these and before :data:`LAST`.
QUEUE: tuple[tuple[str, ...], ...] = (
    ("test_cmake_interfaces.py",),
    ("test_gui.py",),
    ("test_ros1_robot.py", "test_rviz.py"),  # one image_prefix, robocore-it-noetic-: the same base and images
    ("test_official_base.py",),
    ("test_faults.py",),
    ("test_multihost.py",),
    ("test_kilted_restart.py",),
)
#: The groups that go last, in this order: they need the arm64 images (:mod:`arm64_project`), made meanwhile.
LAST: tuple[tuple[str, ...], ...] = (
    ("test_arm64.py", "test_host_build.py", "test_fleet_swarm.py", "test_official_arm64.py"),
)
#: Held exclusively by a quiet test, shared by every build.
LOCK = Path(tempfile.gettempdir()) / f"robocore-it-quiet-{os.getuid()}.lock"
#: robocore commands that build (images, colcon, package tests): they hold the shared lock.
HEAVY_COMMANDS = frozenset({"prepare-base", "stage", "build", "test", "release", "dev"})

_quiet_depth = 0


def lane() -> int:
    """This process's lane: its xdist worker's number (``gw1`` is 1), 0 without workers."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    return int(worker.removeprefix("gw")) if worker.removeprefix("gw").isdigit() else 0


def lanes() -> int:
    """How many lanes the session has (1 without workers)."""
    count = os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")
    return max(1, int(count)) if count.isdigit() else 1


def share(first: int, last: int) -> range:
    """This lane's part of ``first..last`` (inclusive): the lanes split it into equal runs."""
    size = (last - first + 1) // lanes()
    start = first + lane() * size
    return range(start, start + size)


def domain_ids() -> range:
    """The ROS domain IDs this lane's tests draw from (of 100-230)."""
    return share(100, 230)


def ports() -> range:
    """The ports this lane's servers draw from (of 20000-32767, below the kernel's ephemeral range)."""
    return share(20000, 32767)


def group_of(module: str) -> tuple[int, str]:
    """The rank (its place in the queue) and name of the group ``module`` (a file name) belongs to."""
    for rank, group in enumerate(QUEUE):
        if module in group:
            return rank, group[0].removesuffix(".py")
    for rank, group in enumerate(LAST):
        if module in group:
            return len(QUEUE) + 1 + rank, group[0].removesuffix(".py")
    return len(QUEUE), module.removesuffix(".py")


def _locked(mode: int) -> int:
    fd = os.open(LOCK, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o600)
    fcntl.flock(fd, mode)
    return fd


@contextlib.contextmanager
def quiet() -> Iterator[None]:
    """Hold the machine for a timed test: wait until no lane builds, and keep every other lane's builds waiting."""
    global _quiet_depth
    fd = _locked(fcntl.LOCK_EX) if _quiet_depth == 0 else None
    _quiet_depth += 1
    try:
        yield
    finally:
        _quiet_depth -= 1
        if fd is not None:
            os.close(fd)


@contextlib.contextmanager
def heavy() -> Iterator[None]:
    """Mark a build: it waits while another lane runs a quiet test (a quiet test's own builds do not wait)."""
    if _quiet_depth:
        yield
        return
    fd = _locked(fcntl.LOCK_SH)
    try:
        yield
    finally:
        os.close(fd)


@contextlib.contextmanager
def one_at_a_time(name: str) -> Iterator[None]:
    """Hold a lock of this name (every lane's, one at a time): for work that the first lane does and the next
    finds done, such as a shared project's images."""
    path = LOCK.with_name(f"robocore-it-{name}-{os.getuid()}.lock")
    fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o600)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)
