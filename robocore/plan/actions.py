"""What ``run`` does to each container of a host: create, replace, start, keep or remove (pure).

From the planned container specs and what the host runs now (:class:`Existing`), :func:`decide`
picks one :class:`Action` per container; :func:`with_node_restarts` adds the restarts a discovery
kind whose nodes register only when they start (the ROS 1 master) needs after its server restarts.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime

from robocore.plan.containers import ROLE_DISCOVERY, ContainerSpec


@dataclass(frozen=True)
class Existing:
    """A managed container found on a host."""

    name: str
    spec_hash: str | None
    image_id: str
    running: bool
    role: str
    #: When the container last started (Docker's ``State.StartedAt``, RFC 3339), "" when unknown.
    started_at: str = ""


@dataclass(frozen=True)
class Action:
    """One thing ``run`` does (or would do) to one container."""

    verb: str  # create | replace | start | keep | remove
    name: str
    reason: str = ""


def decide(specs: Sequence[ContainerSpec], existing: Sequence[Existing], image_ids: dict[str, str]) -> list[Action]:
    """What to do on one host: obsolete containers are removed first, then specs in order.

    ``image_ids`` maps each spec's image reference to the image ID it should run (a spec
    whose image is not in it is compared by spec hash only).
    """
    found = {e.name: e for e in existing}
    planned = {s.name for s in specs}
    actions = [Action("remove", e.name, "no longer planned on this host") for e in existing if e.name not in planned]
    for spec in specs:
        current = found.get(spec.name)
        wanted_image = image_ids.get(spec.image)
        if current is None:
            actions.append(Action("create", spec.name))
        elif current.spec_hash != spec.spec_hash:
            actions.append(Action("replace", spec.name, "configuration changed"))
        elif wanted_image is not None and current.image_id != wanted_image:
            actions.append(Action("replace", spec.name, "new image"))
        elif not current.running:
            actions.append(Action("start", spec.name, "was stopped"))
        else:
            actions.append(Action("keep", spec.name))
    return actions


#: The verbs that (re)start a container.
STARTS = frozenset({"create", "replace", "start"})


def servers_started(actions: Sequence[Action], specs: Sequence[ContainerSpec]) -> bool:
    """Whether ``actions`` (re)start a discovery server among ``specs``."""
    servers = {s.name for s in specs if s.role == ROLE_DISCOVERY}
    return any(a.name in servers and a.verb in STARTS for a in actions)


_FRACTION = re.compile(r"(\.\d{6})\d*")


def docker_time(text: str) -> datetime | None:
    """A Docker timestamp (RFC 3339, nanoseconds, ``Z``) as an aware datetime; None when empty or unreadable
    (Docker's ``0001-01-01T00:00:00Z`` of a container that never started is read as it is)."""
    try:
        return datetime.fromisoformat(_FRACTION.sub(r"\1", text.strip()).replace("Z", "+00:00"))
    except ValueError:
        return None


def servers_last_started(existing: Sequence[Existing]) -> datetime | None:
    """The latest start of the running discovery servers among ``existing``, None when none runs or it is unknown."""
    times = [docker_time(e.started_at) for e in existing if e.role == ROLE_DISCOVERY and e.running]
    known = [t for t in times if t is not None]
    return max(known) if known else None


def with_node_restarts(actions: Sequence[Action], specs: Sequence[ContainerSpec], *, register_once: bool,
                       elsewhere: bool = False, existing: Sequence[Existing] = (),
                       server_start: datetime | None = None) -> list[Action]:
    """``actions`` with the kept components replaced that a discovery server does not know, when the kind's
    nodes register with it only when they start (``register_once``: the ROS master forgets its nodes when
    it restarts, and they never tell it again).

    Every kept component is replaced when a server (re)starts in this run, on this host or ``elsewhere``
    (another host, earlier in the same run); otherwise those that started before the server's last start
    (a server restarted behind robocore's back: Docker's restart policy, ``docker restart``), from
    ``existing`` (this host's containers) and ``server_start`` (a server on another host).
    """
    servers = {s.name for s in specs if s.role == ROLE_DISCOVERY}
    if not register_once:
        return list(actions)
    if elsewhere or servers_started(actions, specs):
        reason = "the discovery server (re)starts: its nodes register with it only when they start"
        return [Action("replace", a.name, reason) if a.verb == "keep" and a.name not in servers else a
                for a in actions]
    starts = [t for t in (servers_last_started(existing), server_start) if t is not None]
    if not starts:
        return list(actions)
    last = max(starts)
    started = {e.name: docker_time(e.started_at) for e in existing}
    reason = "started before the discovery server's last start: not registered with it"
    out = []
    for action in actions:
        when = started.get(action.name)
        stale = action.verb == "keep" and action.name not in servers and when is not None and when < last
        out.append(Action("replace", action.name, reason) if stale else action)
    return out
