"""The mixed-architecture noetic project of the arm64 suites, and its images made ahead of time.

``test_arm64.py``, ``test_host_build.py`` and the arm64 fleet of ``test_fleet_swarm.py`` share one project name
(``robocore-it-arm64``) and so one set of images: a Debian root per arch (``robocore/<arch>/debian:bookworm-debian``),
a debian base per arch, the talker's (arm64) and listener's (amd64, and arm64 for the fleet) staged images. Made
from nothing they take about ten minutes, most of it the arm64 root's bootstrap under qemu, on one core. Then
``test_official_arm64.py``'s images, on that arm64 root: the arm64 noetic stand-in of the official image
(:mod:`official_standins`), and its project's base and talker image (minutes more under qemu, off the suites'
critical path).

Before all that, the amd64 stand-ins of the official images (``ros:jazzy-ros-base``, ``ros:noetic-ros-base``) for
``test_official_base.py``: about four minutes of Debian bootstraps, downloads and installs that would otherwise be
on the suites' critical path, which that suite's fixture then finds current by their inputs' hash.

Run as a script (``python integration/arm64_project.py``), this module makes those images in throw-away copies of
the projects (``prepare-base`` and ``stage``, which contact no robot host; for the fleet's copy, kept at
:data:`FLEET_BUILT`, ``build`` too), holding :data:`LOCK` while it works.
``scripts/test`` starts it in the background before the lint and unit sessions, and the integration suites'
conftest starts it when nobody has (a plain ``pytest integration``): the other suites run meanwhile, on the other
core. The arm64 suites run last and wait for :data:`LOCK` (:func:`wait_for_images`) before their own
``prepare-base``, which then finds every image current by its content hash and builds nothing. Nothing depends on
the head start for correctness: if it failed or did not run, the suites build what they need themselves.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

import yaml

NAME = "robocore-it-arm64"
#: Held (flock) by the script while it makes the images.
LOCK = Path(tempfile.gettempdir()) / f"robocore-it-arm64-images-{os.getuid()}.lock"
#: The script's output, for the suites to show when it failed.
LOG = LOCK.with_suffix(".log")
#: Placeholder addresses (TEST-NET-1) for the images-only copy: prepare-base and stage contact no host.
NO_HOSTS = ("192.0.2.201", "192.0.2.202")
#: Where the script leaves the Swarm suite's all-arm64 copy of the project, built (its install trees and ccache),
#: for the suite to copy and build again (:func:`built_fleet_project`).
FLEET_BUILT = LOCK.with_name(f"robocore-it-arm64-fleet-{os.getuid()}")
#: The line :data:`LOG` has once the amd64 stand-ins are made.
STANDINS_DONE = "amd64 stand-ins made"


def init_project(root: Path, hosts: Sequence[Mapping[str, object]], *, talker_host: str, server_host: str) -> None:
    """``robocore init`` the template's noetic project on the debian base at ``root`` (its folder name must be
    :data:`NAME`), with ``hosts`` as robot.yaml's hosts, the talker on ``talker_host`` and the ROS master and
    listener on ``server_host``."""
    subprocess.run([sys.executable, "-m", "robocore", "init", str(root), "--defaults", "--distro", "noetic",
                    "--base", "debian"], check=True, capture_output=True, text=True)
    data = yaml.safe_load((root / "robot.yaml").read_text())
    data["hosts"] = [dict(host) for host in hosts]
    data["discovery"] = {"servers": [{"host": server_host}]}
    for comp in data["components"]:
        comp["runs_on"] = talker_host if comp["name"] == "talker" else server_host
    (root / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))


def init_fleet_project(root: Path, ip: str) -> None:
    """The fleet model of the Swarm suite's arm64 robot at ``root``: :func:`init_project` with one arm64 host,
    ``robot`` at ``ip``, running the master, the talker and the listener."""
    init_project(root, [{"name": "robot", "ip": ip, "user": "root", "arch": "arm64"}], talker_host="robot",
                 server_host="robot")


def _holding(path: Path) -> int:
    fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o600)
    fcntl.flock(fd, fcntl.LOCK_EX)
    return fd


def is_running() -> bool:
    """True when a run of this script holds :data:`LOCK` now."""
    try:
        fd = os.open(LOCK, os.O_RDWR | os.O_NOFOLLOW)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)
    return False


def start() -> subprocess.Popen[bytes]:
    """This script started in the background (a process group of its own); returns
    once it holds :data:`LOCK` (or has ended), so that a :func:`wait_for_images` right after it waits."""
    proc = subprocess.Popen([sys.executable, __file__], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.monotonic() + 30
    while proc.poll() is None and not is_running() and time.monotonic() < deadline:
        time.sleep(0.05)
    return proc


def wait_for_images(timeout: float = 3600) -> str | None:
    """Wait until no run of this script holds :data:`LOCK` (``timeout`` seconds at most); return the end of
    its log when it failed (its last line is not ``done``), else None."""
    deadline = time.monotonic() + timeout
    while is_running() and time.monotonic() < deadline:
        time.sleep(2)
    try:
        lines = LOG.read_text(errors="replace").strip().splitlines()
    except OSError:
        return None
    if lines and lines[-1].startswith("done"):
        return None
    return "\n".join(lines[-20:]) or None


def wait_for_standins(timeout: float = 1800) -> None:
    """Wait while a run of this script is making the amd64 stand-ins (``timeout`` seconds at most), so that a suite
    does not build them a second time beside it; returns at once when no run is under way."""
    deadline = time.monotonic() + timeout
    while is_running() and time.monotonic() < deadline:
        with contextlib.suppress(OSError):
            if STANDINS_DONE in LOG.read_text(errors="replace"):
                return
        time.sleep(2)


def make_images() -> None:
    """The amd64 stand-ins (:func:`_official_amd64`), then prepare-base and stage of a throw-away copy of the
    project (placeholder hosts), then the other suites' copies (:func:`_official_arm64`, and the fleet's, kept built
    at :data:`FLEET_BUILT`), printing each step's time."""
    _official_amd64()
    with tempfile.TemporaryDirectory(prefix="robocore-it-images-") as parent:
        root = Path(parent) / NAME
        hosts = [{"name": "robot-x86", "ip": NO_HOSTS[0], "user": "root", "arch": "amd64"},
                 {"name": "robot-arm", "ip": NO_HOSTS[1], "user": "root", "arch": "arm64"}]
        init_project(root, hosts, talker_host="robot-arm", server_host="robot-x86")
        for step in ("prepare-base", "stage"):
            _step(root, step)
        _official_arm64(Path(parent))
        # the Swarm suite's arm64 fleet runs this project on one arm64 host: its listener's image for arm64, and
        # the build under qemu, kept for the suite
        shutil.rmtree(FLEET_BUILT, ignore_errors=True)
        FLEET_BUILT.mkdir(mode=0o700)
        fleet = FLEET_BUILT / NAME
        init_fleet_project(fleet, NO_HOSTS[1])
        for step in ("prepare-base", "stage", "build"):
            _step(fleet, step)
        (FLEET_BUILT / "built").write_text("")


def built_fleet_project() -> Path | None:
    """The all-arm64 copy of the project this script built, when its last run got that far, else None."""
    try:
        ours = FLEET_BUILT.lstat().st_uid == os.getuid() and not FLEET_BUILT.is_symlink()
    except FileNotFoundError:
        return None
    done = ours and (FLEET_BUILT / "built").is_file() and wait_for_images(0) is None
    return FLEET_BUILT / NAME if done else None


def _step(root: Path, step: str, *extra: str) -> None:
    """One robocore step on the project at ``root``, timed; stopped with what it started when this script is."""
    started = time.monotonic()
    argv = [sys.executable, "-m", "robocore", "-p", str(root), step, "--quiet", *extra]
    proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, start_new_session=True)
    try:
        code = proc.wait()
    except BaseException:  # stopped: stop the step and what it started (mmdebstrap, docker build)
        stop(proc, signal.SIGINT, 30)
        raise
    if code != 0:
        raise subprocess.CalledProcessError(code, argv)
    print(f"{root.name} {step}: {time.monotonic() - started:.1f} s", flush=True)


def _official_amd64() -> None:
    """test_official_base's stand-ins, first: that suite runs mid-way through the integration session, the arm64
    suites last. Named with robocore's per-arch name only (the suite's fixture names them as a pull would)."""
    import docker
    import official_standins

    client = docker.from_env(timeout=600)
    for distro in ("jazzy", "noetic"):
        started = time.monotonic()
        official_standins.ensure(client, official_standins.Standin(distro, "amd64"), pin=True)
        print(f"amd64 {distro} stand-in: {time.monotonic() - started:.1f} s", flush=True)
    print(STANDINS_DONE, flush=True)


def _official_arm64(parent: Path) -> None:
    """test_official_arm64's images: the arm64 noetic stand-in (FROM the arm64 root just made; named with robocore's
    per-arch name only, so ``ros:noetic-ros-base``, which another suite may hold on amd64 meanwhile, stays), then
    prepare-base and stage of the talker in a copy of that suite's project."""
    import docker
    import official_standins

    started = time.monotonic()
    client = docker.from_env(timeout=600)  # a step under emulation can be silent for minutes
    official_standins.ensure(client, official_standins.Standin("noetic", "arm64"), pin=True)
    print(f"arm64 noetic stand-in: {time.monotonic() - started:.1f} s", flush=True)
    root = parent / official_standins.ARM64_PROJECT
    subprocess.run([sys.executable, "-m", "robocore", "init", str(root), "--defaults", "--distro", "noetic"],
                   check=True, capture_output=True, text=True)
    official_standins.arm64_project(root, domain=0, port=11311)
    _step(root, "prepare-base")
    _step(root, "stage", "--component", "talker")


def stop(proc: subprocess.Popen[bytes], first: signal.Signals, grace: float) -> None:
    """Send ``first`` to ``proc``'s process group, give it ``grace`` seconds, then SIGKILL; wait for it."""
    for sig, wait in ((first, grace), (signal.SIGKILL, None)):
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, sig)
        try:
            proc.wait(timeout=wait)
            return
        except subprocess.TimeoutExpired:
            continue


def _interrupted(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def main() -> int:
    """Make the images holding :data:`LOCK`, with this process's output going to :data:`LOG`."""
    signal.signal(signal.SIGTERM, _interrupted)  # scripts/test stops it with SIGTERM (its SIGINT is ignored)
    os.nice(19)  # the suites running meanwhile come first; the roots' bootstraps (mmdebstrap, qemu) inherit this
    fd = _holding(LOCK)
    log = os.open(LOG, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW, 0o600)
    for stream in (1, 2):
        os.dup2(log, stream)
    os.close(log)
    try:
        started = time.monotonic()
        make_images()
        print(f"done in {time.monotonic() - started:.1f} s", flush=True)
        return 0
    except subprocess.CalledProcessError as exc:
        print(f"failed: {exc}", flush=True)
        return 1
    finally:
        os.close(fd)


if __name__ == "__main__":
    sys.exit(main())
