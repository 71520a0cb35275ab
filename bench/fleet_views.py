"""Synthetic fleet views for the fleet page's browser tests and its bench: no Docker, no manager.

Two moments of one fleet of ``count`` robots (r1, the canary, alone in wave ``canary``; the others in wave
``rest``), each as ``fleet rollout`` leaves the manager's labels at that moment:

- :func:`rollout_view`: v2 being rolled out over v1. The canary passed its gate on v2; wave ``rest`` was changed
  at once: its robots passed their gates on v2 but r2, still being gated (it runs v1 until its new task runs, and
  has no verdict yet), and the last robot, offline: pending, it runs v1 until it is back.
- :func:`canary_failed_view`: later, v2's rollout done (the last robot still offline and pending), v3 rolled
  out: the canary's v3 talker crashed, so it failed its gate and went back to v2 (gated again, healthy); the rollout
  stopped in wave ``canary``, so no robot of wave ``rest`` was changed. With ``back=False``, the moment just before:
  the canary's gate has failed (its verdict and reason recorded) and it still targets v3, its talker crashed.

Every robot whose last gate ran a probe has the graph it saw (the demo's /listener and /talker, /chatter heard); a
robot being gated or offline has none (its change cleared the labels, and no probe ran). Names and labels are passed
in, so a test can make them hostile.
"""

from __future__ import annotations

from dataclasses import replace

from robocore.plan.fleet_page import ComponentView, FleetView, ReleaseView, RobotView
from robocore.plan.gate_graph import Seen

DIGEST = "@sha256:" + "5e" * 32
REGISTRY = "10.0.0.2:5000"
CANARY_REASON = "talker failed with code 3: task: non-zero exit (3) (restarting)"
NODES, HEARD = ("/listener", "/talker"), ("/chatter",)
OFFLINE_REASON = "offline (robot): Swarm starts it when it is back"
RUNNING = (ComponentView("listener", "running"), ComponentView("talker", "running"))


def releases(*versions: str) -> tuple[ReleaseView, ...]:
    """The recorded releases of ``versions`` (newest first), by digest."""
    recorded = {"v3": "2026-12-06T21:30:00Z", "v2": "2026-12-06T20:10:00Z", "v1": "2026-12-05T09:00:00Z"}

    def images(version: str) -> tuple[tuple[str, str, str], ...]:
        digest = DIGEST.replace("5e", version[-1] * 2, 1)
        return tuple((part, "amd64", f"{REGISTRY}/demo-{part}{digest}") for part in ("listener", "talker", "base"))

    return tuple(ReleaseView(v, recorded[v], images(v)) for v in versions)


def _fleet(count: int, names: list[str] | None, site: str) -> list[RobotView]:
    """Every robot healthy on v2, its gate's probe having seen the demo's graph (wave and labels by position)."""
    names = names or [f"r{i}" for i in range(1, count + 1)]
    return [RobotView(robot=name, wave="canary" if index == 0 else "rest",
                      labels=(("site", site if index % 2 == 0 else "depot"), ("zone", f"z{index % 4}")),
                      running="v2", target="v2", health="healthy", state="online",
                      changed="2026-12-06T20:32:00Z" if index else "2026-12-06T20:30:00Z", components=RUNNING,
                      seen=Seen("v2", "2026-12-06T20:33:10Z" if index else "2026-12-06T20:31:05Z", NODES, HEARD))
            for index, name in enumerate(names)]


def _offline(robot: RobotView) -> RobotView:
    """``robot`` cut off before wave ``rest`` was changed: targeted at v2, still running v1, no probe."""
    return replace(robot, running="v1", health="pending", state="offline, pending", reason=OFFLINE_REASON, seen=None)


def rollout_view(count: int = 6, *, names: list[str] | None = None, site: str = "lab",
                 taken: str = "2026-12-06T20:33:20Z") -> FleetView:
    """v2 being rolled out over v1 (see the module): r2 being gated, the last robot offline and pending."""
    robots = _fleet(count, names, site)
    robots[1] = replace(robots[1], running="v1", health="", state="pending", seen=None,
                        components=(ComponentView("listener", "running"), ComponentView("talker", "starting")))
    robots[-1] = _offline(robots[-1])
    return FleetView(project="demo", taken=taken, robots=tuple(robots), waves=("canary", "rest"),
                     releases=releases("v2", "v1"))


def canary_failed_view(count: int = 6, *, names: list[str] | None = None, site: str = "lab",
                       taken: str = "2026-12-06T21:41:30Z", back: bool = True) -> FleetView:
    """v3's canary failed its gate and is back on v2 (before it went back, with ``back=False``), the rest on v2, the
    last robot still offline (see the module)."""
    robots = _fleet(count, names, site)
    if back:
        robots[0] = replace(robots[0], health="rolled-back", changed="2026-12-06T21:41:07Z", reason=CANARY_REASON,
                            seen=Seen("v2", "2026-12-06T21:41:20Z", NODES, HEARD))  # what the gate of the way back saw
    else:  # the talker's v3 task crashed (no task runs it), the gate failed before its probe: no graph
        robots[0] = replace(robots[0], running="-", target="v3", health="failed", changed="2026-12-06T21:40:30Z",
                            reason=CANARY_REASON, seen=None,
                            components=(ComponentView("listener", "running"), ComponentView("talker", "failed")))
    robots[-1] = _offline(robots[-1])
    return FleetView(project="demo", taken=taken, robots=tuple(robots), waves=("canary", "rest"),
                     releases=releases("v3", "v2", "v1"))
