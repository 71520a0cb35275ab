"""Timing a component's way back in place: from the new process's start, as Docker records it
(``State.StartedAt``), to the listener's first greeting of it, as Docker's log timestamps record it. Both clocks
are the daemon's, so the test process's own scheduling on a busy machine adds nothing.

Shared by the suites that time the ways back on a one-host robot (``test_shm_kills``: Jazzy with shared memory;
``test_kilted_restart``: Fast DDS 3.x; ``test_ros1_robot``: the ROS 1 master and TCPROS).
"""

from __future__ import annotations

import os
import signal
import statistics
import time
from collections.abc import Callable
from typing import Any

import ci_times
import lanes

from robocore.plan import naming
from robocore.plan.starts import docker_epoch
from robocore.testing.domains import domain_of

#: What the template's listeners log for each greeting (rclpy and rospy alike), before the talker's number.
HEARD = "I heard: hello from talker #"
#: Seconds a talker runs before it is crashed again: Docker doubles a restart policy's delay for a container
#: that ran less than 10 s, which would time Docker's back-off, not the way back.
POLICY_SPACING = 10.5


class Pair:
    """The talker and listener containers of one deployment, by name."""

    def __init__(self, client: Any, talker: str, listener: str) -> None:
        self.client, self.talker_name, self.listener_name = client, talker, listener

    def talker(self) -> Any:
        return self.client.containers.get(self.talker_name)

    def kill_and_start(self) -> None:
        """SIGKILL the talker's container, then start it again in place 0.3 s later."""
        talker = self.talker()
        talker.kill()
        time.sleep(0.3)
        talker.start()

    def crash(self) -> None:
        """Kill the talker's process from outside Docker, as a crash ends it: its restart policy starts it again."""
        os.kill(self.talker().attrs["State"]["Pid"], signal.SIGKILL)

    def greetings(self) -> list[tuple[str, int]]:
        """(Docker's timestamp, talker number) of each greeting in the listener's log, oldest first."""
        text = self.client.containers.get(self.listener_name).logs(timestamps=True).decode(errors="replace")
        found = []
        for line in text.splitlines():
            number = line.rpartition("#")[2].strip()
            if HEARD in line and number.isdigit():
                found.append((line.split(" ", 1)[0], int(number)))
        return found

    def wait_heard(self, timeout: float = 30.0) -> None:
        """Until the listener has heard the talker at least once."""
        deadline = time.monotonic() + timeout
        while not self.greetings():
            assert time.monotonic() < deadline, "the listener never heard the talker"
            time.sleep(0.2)

    def start_to_heard(self, mark: int, previous_start: str, timeout: float = 30.0) -> float:
        """Seconds from the talker's new start (its ``StartedAt`` no longer ``previous_start``) to the listener's
        first greeting logged at or after it (after the log's first ``mark`` greetings), both as Docker recorded
        them. Every way back ends the old process before the new one starts, so what the listener logs after the
        new start is the new process's (its count starts again, but the listener may miss its first greetings,
        so the count cannot tell)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            started = self.talker().attrs["State"]["StartedAt"]
            if started != previous_start:
                start = docker_epoch(started)
                new = [when for when in (docker_epoch(stamp) for stamp, _ in self.greetings()[mark:]) if when >= start]
                if new:
                    return new[0] - start
            time.sleep(0.1)
        raise AssertionError(f"the talker was not heard again within {timeout} s: {self.greetings()[-5:]}; "
                             f"{self.talker_state()}; {others_running(self.client, self.talker_name)}")

    def talker_state(self) -> str:
        """What Docker says of the talker now, and the end of its log: when a way back is not heard, whether the
        talker runs (and since when) or failed at its start."""
        talker = self.talker()
        state = talker.attrs["State"]
        tail = talker.logs(tail=5).decode(errors="replace").strip().replace("\n", " | ")
        return (f"talker {state.get('Status')} since {state.get('StartedAt')} (restarts "
                f"{talker.attrs.get('RestartCount')}, last exit {state.get('ExitCode')}), its log ends {tail[-600:]!r}")

    def timed_rounds(self, way: Callable[[], None], name: str, rounds: int, spacing: float = 0.0) -> list[float]:
        """``rounds`` times: the talker brought back ``way``, then seconds from its start to heard. ``spacing``:
        seconds the talker runs from its start before the next round (or longer: in a quiet test the other lanes
        work meanwhile, :func:`lanes.untimed`, and the round waits for their phases under way to end)."""
        seconds, busy = [], []
        for _ in range(rounds):
            previous = self.talker().attrs["State"]["StartedAt"]
            left = spacing - (time.time() - docker_epoch(previous))
            if left > 0:
                with lanes.untimed():  # the talker running times nothing: the other lanes may work meanwhile
                    time.sleep(left)
            mark = len(self.greetings())
            before = ci_times.busy_jiffies()
            way()
            try:
                seconds.append(self.start_to_heard(mark, previous))
            except AssertionError as failed:
                done = " ".join(f"{t:.2f} (busy {b} %)" for t, b in zip(seconds, busy, strict=True)) or "none"
                raise AssertionError(f"{name}, round {len(seconds) + 1} of {rounds} (rounds before: {done}; machine "
                                     f"busy {busy_share(before, ci_times.busy_jiffies())} % since): {failed}") from None
            busy.append(busy_share(before, ci_times.busy_jiffies()))
        # the machine's busy CPU over each round (all cores, every process): what to look at when a round is slow
        print(f"FIGURE {name}: start to heard s: median {statistics.median(seconds):.2f}, "
              f"rounds {' '.join(f'{t:.2f}' for t in seconds)}; machine busy % {' '.join(busy)}")
        return seconds


def others_running(client: Any, talker: str) -> str:
    """The other robocore containers running on this machine's daemon (another lane's robots, this module's other
    copy) with their ROS domains: robots of one domain on one host share its ports."""
    project = talker.rsplit("-", 1)[0]
    seen = []
    for container in client.containers.list(filters={"label": naming.LABEL_ROLE}, ignore_removed=True):
        if container.name.startswith(project + "-"):
            continue
        domain = domain_of(container)
        seen.append(f"{container.name} (domain {'-' if domain is None else domain})")
    return f"also running here: {', '.join(sorted(seen)) or 'nothing of robocore'}"


def busy_share(before: tuple[int, int] | None, after: tuple[int, int] | None) -> str:
    """The machine's busy share of its CPU time between two :func:`ci_times.busy_jiffies` readings, in per cent
    ("?" where there is no /proc/stat)."""
    if before is None or after is None or after[1] <= before[1]:
        return "?"
    return f"{100 * (after[0] - before[0]) / (after[1] - before[1]):.0f}"


def in_place_ways(pair: Pair, label: str, rounds: int) -> tuple[list[float], list[float]]:
    """``rounds`` times each: the talker SIGKILLed and started again, then crashed and started again by its
    restart policy; the seconds from its start to heard of each way."""
    killed = pair.timed_rounds(pair.kill_and_start, f"{label} SIGKILL + start", rounds)
    crashed = pair.timed_rounds(pair.crash, f"{label} crash, restart policy", rounds, spacing=POLICY_SPACING)
    return killed, crashed
