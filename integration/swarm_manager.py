"""Helpers of the Swarm suite's test of ``fleet logs`` and ``fleet connect``: a robot host's ssh port closed from
outside (the robot itself and its swarm traffic untouched), and lines read from a following command as they come."""

from __future__ import annotations

import contextlib
import queue
import subprocess
import threading
import time
from collections.abc import Callable, Iterator

from robot_host.hosts import RobotFleet


@contextlib.contextmanager
def ssh_closed(hosts: RobotFleet, index: int) -> Iterator[None]:
    """Robot host ``index`` refuses every ssh packet (TCP port 22 in, on its eth0) while the block lasts: what
    reaches the robot over ssh fails, what reaches it through the swarm does not."""
    container = hosts.hosts[index].container.get_wrapped_container()
    rule = ["INPUT", "-i", "eth0", "-p", "tcp", "--dport", "22", "-j", "REJECT", "--reject-with", "tcp-reset"]
    code, out = container.exec_run(["iptables", "-I", *rule])
    assert code == 0, out
    try:
        yield
    finally:
        code, out = container.exec_run(["iptables", "-D", *rule])
        assert code == 0, out


def lines_until(proc: subprocess.Popen[str], found: Callable[[list[str]], bool], timeout: float) -> list[str]:
    """The lines ``proc`` printed on stdout until ``found(lines)`` holds, its stdout ended or ``timeout`` seconds
    passed (read in a thread, so a quiet stream never blocks the test past its time)."""
    assert proc.stdout is not None
    stream = proc.stdout
    got: queue.Queue[str | None] = queue.Queue()

    def read() -> None:
        for line in stream:
            got.put(line.rstrip("\n"))
        got.put(None)

    threading.Thread(target=read, daemon=True).start()
    lines: list[str] = []
    deadline = time.monotonic() + timeout
    while not found(lines) and time.monotonic() < deadline:
        try:
            line = got.get(timeout=max(0.0, deadline - time.monotonic()))
        except queue.Empty:
            break
        if line is None:
            break
        lines.append(line)
    return lines
