"""Faults on the fleet's side for the Swarm suite: the registry stopped during a wave, the manager's daemon restarted
in the middle of a rollout, a robot host's power cut during its update; the figures each test measured.

The manager and the robot host whose power is cut have a disk of their own (``RobotFleet(disks=...)``): their
/var/lib/docker, and so the swarm's state and the images, outlive a restart as a machine's do; each comes back at its
address (nothing else joins the suite's network meanwhile), which ``RobotFleet.power_on`` checks.

The suite's registry is Debian's ``docker-registry`` on this machine (:func:`local_registry.serve_registry`), which
every host reaches as ``127.0.0.1:PORT`` through an ssh tunnel. Stopping that process is the registry going down as
a team's would: each robot's daemon then finds the port closed at the far end of its tunnel (connection refused or
reset), as for a registry host that is down. It is started again afterwards, on the same port with the same
configuration and data, so the module's later tests find it as before.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from deploy_helpers import wait_for


def serving(address: str) -> bool:
    """Whether the registry at ``address`` (``127.0.0.1:PORT``) accepts a connection (with TLS or without)."""
    host, port = address.rsplit(":", 1)
    with contextlib.suppress(OSError), socket.create_connection((host, int(port)), timeout=2):
        return True
    return False


def registry_process(address: str) -> tuple[int, list[str]]:
    """The pid and argv of the ``docker-registry serve CONFIG`` serving ``address`` that this process started (its
    child: nothing another run started is touched)."""
    listen = f"addr: {address}\n"
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        with contextlib.suppress(OSError):
            argv = (entry / "cmdline").read_bytes().decode(errors="replace").split("\0")[:-1]
            parent = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            if (parent == os.getpid() and len(argv) == 3 and Path(argv[0]).name == "docker-registry"
                    and argv[1] == "serve" and listen in Path(argv[2]).read_text()):
                return int(entry.name), argv
    raise AssertionError(f"no docker-registry of this run serves {address}")


@contextlib.contextmanager
def registry_down(address: str, restarted: list[subprocess.Popen[bytes]]) -> Iterator[None]:
    """The registry at ``address`` stopped (SIGTERM, then no answer seen) for the block, then started again from the
    same command line; the new process is appended to ``restarted`` (whoever owns the list stops it)."""
    pid, argv = registry_process(address)
    os.kill(pid, signal.SIGTERM)
    assert wait_for(lambda: not serving(address), 15, interval=0.2), f"the registry at {address} still answers"
    try:
        yield
    finally:
        restarted.append(subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        assert wait_for(lambda: serving(address), 30, interval=0.2), f"the registry at {address} did not come back"


def stop_all(processes: list[subprocess.Popen[bytes]]) -> None:
    """Stop the registries :func:`registry_down` started again."""
    for process in processes:
        process.terminate()
        with contextlib.suppress(subprocess.TimeoutExpired):
            process.wait(timeout=10)
        if process.poll() is None:
            process.kill()
            process.wait()


#: Where the fault tests append their figures (one JSON object a line), when set: ``bench/fleet_faults.py`` sets it
#: and records what they measured.
FIGURES = "ROBOCORE_FAULT_FIGURES"


def record_fault(fault: str, *, left: int, robots: int, healthy: float, **more: float) -> None:
    """Append the figures of ``fault`` to the file :data:`FIGURES` names (nothing when it is not set): ``left`` of
    ``robots`` robots were left without a healthy release, the fleet was healthy ``healthy`` seconds after the
    rollout's start; ``more``: other seconds the test measured."""
    path = os.environ.get(FIGURES)
    print(f"{fault}: robots left without a healthy release: {left} of {robots}; healthy fleet after {healthy:.1f} s",
          more)
    if path:
        with open(path, "a", encoding="utf-8") as out:
            out.write(json.dumps({"fault": fault, "left": left, "robots": robots, "healthy": round(healthy, 1),
                                  **{k: round(v, 1) for k, v in more.items()}}) + "\n")


class Watch:
    """``look()`` called again and again in a thread until :meth:`stop` (each look's result kept with its time): what
    ``fleet status`` said all along a fault, to be checked afterwards."""

    def __init__(self, look: Callable[[], Any], interval: float = 1.0) -> None:
        self.seen: list[tuple[float, Any]] = []
        self._look, self._interval = look, interval
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._done.is_set():
            self.seen.append((time.monotonic(), self._look()))
            self._done.wait(self._interval)

    def stop(self) -> list[tuple[float, Any]]:
        """Stop looking (the look under way ends first); every look's (time, result)."""
        self._done.set()
        self._thread.join(timeout=120)
        return self.seen
