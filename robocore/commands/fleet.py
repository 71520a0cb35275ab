"""``fleet VERB``: the fleet task's verbs, each handed to its command module."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from robocore.commands.support.context import Options
from robocore.errors import UsageError

#: The verbs of ``robocore fleet``.
VERBS = ("join", "rollout", "status", "rollback")


def fleet(options: Options, *, verb: str, version: str | None, robots: Sequence[str]) -> Any:
    """Run ``fleet VERB``: join, rollout VERSION, status, rollback [ROBOT...]."""
    from robocore.commands import fleet_join, fleet_rollout, fleet_status

    if verb == "join":
        return fleet_join.join(options)
    if verb == "rollout":
        return fleet_rollout.rollout(options, version=version or "")
    if verb == "status":
        return fleet_status.status(options)
    if verb == "rollback":
        return fleet_rollout.rollback(options, robots=list(robots))
    raise UsageError(f"fleet needs one of {', '.join(VERBS)}", hint="robocore fleet status")
