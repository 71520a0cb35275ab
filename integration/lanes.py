"""How the integration suites share one machine: lanes, one queue, and quiet tests.

The integration session runs on pytest-xdist workers (``-n LANES --dist loadgroup --no-loadscope-reorder``, in the
noxfile), each a *lane*: when a lane has finished its group of modules it takes the next group from one queue, in
:data:`QUEUE`'s order. A suite spends much of its time waiting (a gate, a rollout, a fault's window, a download),
and the other lane works meanwhile.

- :data:`QUEUE`: groups of modules that build most, the longest first, while the arm64 images are made in the
  background (both cores are busy anyway); the modules of one group run one after the other in one lane because
  they share a project name and its images, containers or hosts. A module not named here is a group of its own,
  handed out next; then :data:`LATE`, the groups whose timed tests are most of their time, once the background
  work is likelier done; then :data:`LAST` (they need the arm64 images).
- Quiet tests (``@pytest.mark.quiet``) time what they prove (a node heard again within 2 s, a server's hold, no gap
  over 1.2 s): while one runs, every other lane stands still between two tests (:func:`quiet`, :func:`working`), as
  on the quiet machine their bounds were set on. Each phase of every other test (set-up, body, teardown: the
  builds of fixtures included) holds the machine shared; a quiet test's body holds it alone. A quiet test waits
  for the phases under way to end, and a lane's next phase waits behind a waiting quiet test (:data:`TURNSTILE`),
  so that a quiet test is never starved by lanes that take turns. A quiet body gives the machine back for the
  stretches it does not time (:func:`untimed`: a bring-up, a talker left running 10 s before its next crash), so
  the other lanes stand still only while something is timed.
- A module of :data:`ALONE` runs with no other module under way (:func:`hold_alone`).
- A module with quiet tests never runs beside a module of :data:`BUSY`, whose work goes on outside its tests'
  phases (:func:`hold_module`): the one waits for the other to end.
- Each lane draws ROS domain IDs and ports from a range of its own (:func:`domain_ids`, :func:`ports`), so that two
  lanes never pick the same one at the same moment; within a lane, domains are handed out in turn (:func:`new_domain`).
"""

from __future__ import annotations

import contextlib
import fcntl
import itertools
import os
import random
import socket
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

#: Groups of modules in the order the lanes take them first. A module not listed anywhere is a group of its own,
#: handed out after these and before :data:`LATE`.
QUEUE: tuple[tuple[str, ...], ...] = (
    ("test_cmake_interfaces.py",),
    ("test_gui.py",),
    ("test_official_base.py",),
    ("test_multihost.py",),
)
#: The groups whose quiet (timed) tests are most of their time, after the unlisted ones, in this order.
LATE: tuple[tuple[str, ...], ...] = (
    ("test_arm64.py", "test_host_build.py"),  # the mixed robot (host build edits the project arm64 made): its images
    # are made by then, and it is done before the Swarm suite, which shares its project (:data:`ARM64_PROJECT`)
    ("test_ros1_robot.py", "test_rviz.py"),  # one image_prefix, robocore-it-noetic-: the same base and images
    ("test_faults.py",),
    ("test_kilted_restart.py",),
    ("test_shm_kills.py",),
)
#: The groups that go last, in this order (they need the arm64 images, :mod:`arm64_project`, made meanwhile): the
#: Swarm suite, the longest, then the official arm64 base.
LAST: tuple[tuple[str, ...], ...] = (
    ("test_fleet_swarm.py",),
    ("test_official_arm64.py",),
)
#: The modules that need the arm64 images made in the background (:mod:`arm64_project`).
ARM64_IMAGES = frozenset({"test_arm64.py", "test_host_build.py", "test_fleet_swarm.py", "test_official_arm64.py"})
#: The modules of one project name, ``robocore-it-arm64``, whose ``stage`` tags its images for its own robots (the
#: mixed robot's listener is amd64, the Swarm fleet's arm64, under one tag): two of them at once in two lanes would
#: each run the other's image. Each holds :func:`hold_project` from its first test's set-up to its last test's
#: teardown, taken before the machine's lock (a lane waiting for it holds nothing another lane waits for). Seen
#: in CI: the Swarm suite's arm64 release refused "image robocore-it-arm64-listener:latest is of arch amd64".
ARM64_PROJECT = frozenset({"test_arm64.py", "test_host_build.py", "test_fleet_swarm.py"})
#: The modules whose own work goes on beside their tests' phases, between them and across them: the Swarm suite's
#: fixture builds, pushes and pulls its releases in threads (the arm64 ones under emulation) while ten
#: Docker-in-Docker hosts boot, and its fleets then run, under emulation too. A quiet test holds the machine alone
#: only from the other lanes' *phases*, so a module with quiet tests never runs beside one of these
#: (:func:`hold_module`): what a quiet test times must not share the machine with builds under emulation.
BUSY = frozenset({"test_fleet_swarm.py"})
#: The modules that run with no other module under way in any lane (the other lanes wait between two modules):
#: the shm suite's ways back, timed against a 2 s bound, passed alone every time (medians 0.7-0.9 s, the machine 45 %
#: busy) and failed in three CI runs in a row beside other modules with the machine as idle (one round of 1.6-30 s
#: and more, 18 % busy over the module): something of another module's robots reaches them, not the CPU.
ALONE = frozenset({"test_shm_kills.py"})
#: Held shared by every module and exclusively by a module of :data:`ALONE`, from its first test's set-up to its
#: last test's teardown (:func:`hold_alone`), before any other lock.
MACHINE_LOCK = Path(tempfile.gettempdir()) / f"robocore-it-alone-modules-{os.getuid()}.lock"
#: Held shared by a module with quiet tests and exclusively by a module of :data:`BUSY`, each from its first test's
#: set-up to its last test's teardown (:func:`hold_module`).
MODULES_LOCK = Path(tempfile.gettempdir()) / f"robocore-it-timed-modules-{os.getuid()}.lock"
#: Held exclusively by a quiet test's body, shared by every other phase of a test (a build's included).
LOCK = Path(tempfile.gettempdir()) / f"robocore-it-quiet-{os.getuid()}.lock"
#: Passed (held exclusively) by a quiet test on its way to :data:`LOCK`, and by every other lane, shared, on its
#: way to :data:`LOCK` shared: a quiet test that waits holds it, so the lanes cannot keep :data:`LOCK` taken
#: between them, one phase after another, for ever (flock favours no waiter).
TURNSTILE = LOCK.with_name(f"robocore-it-turnstile-{os.getuid()}.lock")

_held = 0  # how deep this process is in quiet() or working(): only the outermost takes the lock
_hold: list[int] = []  # the outermost hold: [descriptor of LOCK, its mode]
_alone = [0.0, 0.0]  # seconds this process held LOCK exclusively so far, and since when it holds it (0: it does not)


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
    """The ROS domain IDs this lane's tests draw from (of 1-49): a participant of domain D binds UDP ports from
    7400 + 250 D, so domains above 101 bind in the kernel's ephemeral range (32768 and up), where any client's
    socket may hold the port first and the discovery server fails to start; 50-101 would bind among
    :func:`ports`."""
    return share(1, 49)


#: This lane's next domain ID, as a count from a random start (so that two sessions on one machine seldom begin alike).
_domain_turn = itertools.count(random.randrange(1000))
#: The domains this lane handed out, held as the pytest plugin's runs hold theirs (its loopback ports): held until
#: the lane hands the same domain out again, a whole turn of its IDs later.
_domain_holds: dict[int, socket.socket] = {}


def new_domain() -> int:
    """A ROS domain ID of :func:`domain_ids` for one deployment: the IDs are handed out in turn, so two deployments
    alive at once in one lane (a module's robot and a test's own copy) never share one, and each is held the way
    the pytest plugin's runs hold theirs (:func:`robocore.testing.domains.hold_domain`), so that no run of the
    plugin, in this lane or another, is handed it meanwhile (seen: a module's robot of the plugin and a test's own
    copy both in domain 32). Robots on host networking and host IPC that share a domain share Fast DDS's UDP ports
    and its shared-memory ports in /dev/shm, and a restart on one may then be timed against the other's traffic."""
    from robocore.testing.domains import hold_domain

    ids = domain_ids()
    for _ in range(len(ids)):
        domain = ids[next(_domain_turn) % len(ids)]
        previous = _domain_holds.pop(domain, None)
        if previous is not None:
            previous.close()
        holder = hold_domain(domain)
        if holder is not None:
            _domain_holds[domain] = holder
            return domain
    raise RuntimeError(f"every ROS domain of this lane ({ids.start}-{ids.stop - 1}) is held by a test run here")


def ports() -> range:
    """The ports this lane's servers draw from (of 20000-32767, below the kernel's ephemeral range)."""
    return share(20000, 32767)


def group_of(module: str) -> tuple[int, str]:
    """The rank (its place in the queue) and name of the group ``module`` (a file name) belongs to."""
    for start, groups in ((0, QUEUE), (len(QUEUE) + 1, LATE), (len(QUEUE) + 1 + len(LATE), LAST)):
        for rank, group in enumerate(groups):
            if module in group:
                return start + rank, group[0].removesuffix(".py")
    return len(QUEUE), module.removesuffix(".py")


def _locked(path: Path, mode: int) -> int:
    fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o600)
    fcntl.flock(fd, mode)
    return fd


def _through_turnstile(mode: int, fd: int | None = None) -> int:
    """:data:`LOCK` in ``mode``, taken through :data:`TURNSTILE` (in the same mode, let go of once :data:`LOCK` is
    held); on ``fd`` when given (which holds nothing of :data:`LOCK` now), else on a new descriptor. Nothing of
    :data:`LOCK` is held while waiting at the turnstile, so two lanes never wait for each other there."""
    gate = _locked(TURNSTILE, mode)
    try:
        if fd is None:
            return _locked(LOCK, mode)
        fcntl.flock(fd, mode)
        return fd
    finally:
        os.close(gate)


def _now_alone(mode: int) -> None:
    """Count the seconds :data:`LOCK` is held exclusively: start the count (``mode`` exclusive) or end it."""
    if _alone[1]:
        _alone[0] += time.monotonic() - _alone[1]
    _alone[1] = time.monotonic() if mode == fcntl.LOCK_EX else 0.0


@contextlib.contextmanager
def _holding(mode: int) -> Iterator[None]:
    """:data:`LOCK` in ``mode`` for this process, through :data:`TURNSTILE`; re-entrant: a nested call holds nothing
    more (a second flock of this process could wait behind a quiet test that waits for the first: a deadlock)."""
    global _held
    if _held:
        _held += 1
        try:
            yield
        finally:
            _held -= 1
        return
    fd = _through_turnstile(mode)
    _hold[:] = [fd, mode]
    _now_alone(mode)
    _held = 1
    try:
        yield
    finally:
        _held = 0
        _now_alone(fcntl.LOCK_UN)
        _hold.clear()
        os.close(fd)


def quiet() -> contextlib.AbstractContextManager[None]:
    """Hold the machine for a timed test's body: wait until every other lane stands between two test phases, and
    keep them there until the body ends."""
    return _holding(fcntl.LOCK_EX)


def working() -> contextlib.AbstractContextManager[None]:
    """Hold the machine shared, for a test's phase: it waits while another lane runs a quiet test's body (and from
    the moment one waits to start)."""
    return _holding(fcntl.LOCK_SH)


@contextlib.contextmanager
def untimed() -> Iterator[None]:
    """A stretch of a quiet test's body that times nothing (a bring-up, a wait for a talker to have run 10 s): the
    other lanes may work meanwhile, and the machine is held alone again, once their phases under way have ended,
    before the body goes on to what it times. Anywhere else (a phase that holds the machine shared, no phase at
    all) it changes nothing."""
    if not _hold or _hold[1] != fcntl.LOCK_EX:
        yield
        return
    fd = _hold[0]
    fcntl.flock(fd, fcntl.LOCK_SH)  # shared: the other lanes' phases start now
    _hold[1] = fcntl.LOCK_SH
    _now_alone(fcntl.LOCK_SH)
    try:
        yield
    finally:
        fcntl.flock(fd, fcntl.LOCK_UN)  # nothing held at the turnstile (another quiet test may be ahead there)
        _through_turnstile(fcntl.LOCK_EX, fd)
        _hold[1] = fcntl.LOCK_EX
        _now_alone(fcntl.LOCK_EX)


def alone_seconds() -> float:
    """The seconds this process held the machine alone (quiet tests' bodies, less their untimed stretches) so far."""
    return _alone[0] + (time.monotonic() - _alone[1] if _alone[1] else 0.0)


def hold_project(name: str) -> int:
    """Take the lock of project ``name`` (every lane's, one at a time) and return its descriptor, for
    :func:`let_go`: held across tests, from a module's first set-up to its last teardown."""
    return _locked(LOCK.with_name(f"robocore-it-project-{name}-{os.getuid()}.lock"), fcntl.LOCK_EX)


def hold_alone(module: str) -> int:
    """:data:`MACHINE_LOCK` for module ``module`` (a file name), for :func:`let_go`: exclusively for a module of
    :data:`ALONE`, else shared. The first lock a module takes, at its first test's set-up, so a lane waiting here
    holds nothing at all."""
    return _locked(MACHINE_LOCK, fcntl.LOCK_EX if module in ALONE else fcntl.LOCK_SH)


def hold_module(module: str, timed: bool) -> int | None:
    """What module ``module`` (a file name) holds from its first test's set-up to its last teardown, for
    :func:`let_go`: :data:`MODULES_LOCK` shared when it has quiet tests (``timed``), exclusively when it is of
    :data:`BUSY`, else nothing (None). Taken before the machine's lock, as :func:`hold_project` is, so a lane waiting
    here holds nothing another lane waits for."""
    if module in BUSY:
        return _locked(MODULES_LOCK, fcntl.LOCK_EX)
    return _locked(MODULES_LOCK, fcntl.LOCK_SH) if timed else None


def let_go(fd: int) -> None:
    """Let go of a lock :func:`hold_project`, :func:`hold_alone` or :func:`hold_module` took."""
    os.close(fd)


@contextlib.contextmanager
def one_at_a_time(name: str) -> Iterator[None]:
    """Hold a lock of this name (every lane's, one at a time): for work that the first lane does and the next
    finds done, such as a shared project's images."""
    path = LOCK.with_name(f"robocore-it-{name}-{os.getuid()}.lock")
    fd = _locked(path, fcntl.LOCK_EX)
    try:
        yield
    finally:
        os.close(fd)
