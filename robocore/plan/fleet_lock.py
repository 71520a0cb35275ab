"""A robot's "not now" (pure): its update lock, read by a probe on the robot, and why a robot is held back.

A robot says "not now" through its own ROS graph, with no robocore code in its nodes: any node publishes
``true`` on :data:`LOCK_TOPIC` (``std_msgs/Bool``), latched (ROS 2: reliable, transient-local durability; ROS 1:
``latch=True``), and ``false`` (or ends) when the robot may be restarted. Before ``fleet rollout`` touches a robot,
a one-shot probe service on the robot (the health gate's mechanism: the release's base image on the host of its
first discovery server, an observer of its graph) subscribes to the topic: a ``true`` from any publisher is a
lock; no message within :data:`LOCK_WAIT` seconds of subscribing, or only ``false``, is no lock.

:func:`hold_reason` decides, from the robot's maintenance window (:mod:`robocore.plan.fleet_windows`) and its lock,
whether the robot is held back and why; :func:`past_busy` whether it has been held longer than
``rollout.timeouts.busy``.
"""

from __future__ import annotations

from dataclasses import replace

from robocore.config.model import Robot
from robocore.plan.fleet_windows import WindowState
from robocore.plan.swarm_services import (
    PROBE_SCRIPT,
    GateCheck,
    Release,
    ServiceSpec,
    probe_service,
    probe_verdict,
    resource_for,
)
from robocore.project import Project

#: The topic a robot's nodes hold its update lock on.
LOCK_TOPIC = "/robocore/update_lock"
#: Seconds the probe waits for a latched message after it subscribed: a latched value reaches a new subscriber
#: as soon as it has discovered the publisher (well under a second on a robot's own discovery server or master),
#: so this bounds discovery, not the robot's answer. No message within it is no lock.
LOCK_WAIT = 5.0
#: Seconds between two questions to a robot that holds its lock (each one a probe task on the robot).
LOCK_POLL = 1.0
#: The lock probe of each discovery kind (a file of :mod:`robocore.resources`).
LOCK_RESOURCES = {"fastdds": "fleet-lock-probe", "rosmaster": "fleet-lock-probe-ros1"}
#: Service label: since when (UTC, ISO 8601) a robot's update is held back, while ``fleet rollout`` waits for it.
LABEL_BUSY = "dev.robocore.fleet.busy-since"
#: The health verdict of a robot left as it was because it stayed busy past ``rollout.timeouts.busy``.
BUSY = "busy"


def lock_resource(instance: Robot) -> str:
    """The lock probe script (a resource name) for ``instance``'s discovery kind; KeyError for a kind with none."""
    return resource_for(instance, LOCK_RESOURCES, "an update-lock probe")


def lock_probe_service(project: Project, robot: str, instance: Robot, release: Release, script: str,
                       suffix: str) -> ServiceSpec:
    """The one-shot service that asks ``robot`` for its update lock: the health probe's service (same host, image,
    environment and DDS files) running the lock probe ``script``."""
    spec = probe_service(project, robot, instance, release, GateCheck((), (), LOCK_WAIT), script, f"lock-{suffix}")
    return replace(spec, args=("python3", PROBE_SCRIPT, "--topic", LOCK_TOPIC, "--wait", f"{LOCK_WAIT:g}"))


def lock_answer(output: str, state: str = "", exit_code: int | None = None) -> tuple[bool | None, str]:
    """The lock probe's answer: (locked, error), locked None when it could not tell. From its output, else from how
    its task ended (``state``, ``exit_code``: it exits 0 when free and 1 when locked), as its output can miss the
    manager (seen on a robot that had reconnected: the manager could not stream its node's logs)."""
    verdict = probe_verdict(output)
    if verdict is None:
        if state == "complete" and exit_code in (0, None):
            return False, ""
        if state == "failed" and exit_code == 1:
            return True, ""
        return None, "the update-lock probe printed no answer" + (f" ({state})" if state else "")
    locked = verdict.get("locked")
    error = str(verdict.get("error") or "")
    if not isinstance(locked, bool) or error:
        return None, error or "the update-lock probe could not tell"
    return locked, ""


def hold_reason(window: WindowState | None, locked: bool | None, error: str = "") -> str:
    """Why a robot is held back ("" when it may be updated now): its maintenance window is closed, it holds its
    update lock, or its lock could not be read (held: a robot that cannot be asked is not restarted unasked)."""
    if window is not None and not window.open:
        return f"outside its maintenance window: {window.reason}"
    if locked is None:
        return f"cannot read its update lock ({error or 'no answer'})"
    return f"holds its update lock ({LOCK_TOPIC})" if locked else ""


def past_busy(held_for: float, busy: float) -> bool:
    """Whether a robot held back ``held_for`` seconds is past ``rollout.timeouts.busy`` (``busy`` seconds)."""
    return held_for > busy
