"""What ``run`` does to each container of a host: create, replace, start, keep or remove (pure).

From the planned container specs and what the host runs now (:class:`Existing`), :func:`decide`
picks one :class:`Action` per container; :func:`with_node_restarts` adds the restarts a discovery
kind whose nodes register only when they start (the ROS 1 master) needs after its server restarts.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass
from datetime import datetime

from robocore.plan.containers import ContainerSpec
from robocore.plan.naming import ROLE_DISCOVERY
from robocore.plan.starts import started_before_servers


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


def in_stages(actions: Sequence[Action], servers: Collection[str]) -> list[list[Action]]:
    """``actions`` of one host grouped in the order ``run`` takes them: the removals, then each discovery server
    of ``servers`` alone (one is serving before anything after it starts), then every other container.

    The actions inside a stage do not depend on each other, so they can be taken side by side; ``keep`` actions
    (nothing to do) and empty stages are left out.
    """
    removals = [a for a in actions if a.verb == "remove"]
    serving = [[a] for a in actions if a.name in servers and a.verb not in ("remove", "keep")]
    rest = [a for a in actions if a.name not in servers and a.verb not in ("remove", "keep")]
    return [stage for stage in (removals, *serving, rest) if stage]


#: The verbs that (re)start a container.
STARTS = frozenset({"create", "replace", "start"})


def servers_started(actions: Sequence[Action], servers: Collection[str]) -> bool:
    """Whether ``actions`` (re)start one of the discovery server containers named in ``servers``."""
    return any(a.name in servers and a.verb in STARTS for a in actions)


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
    if not register_once:
        return list(actions)
    servers = {s.name for s in specs if s.role == ROLE_DISCOVERY}
    if elsewhere or servers_started(actions, servers):
        reason = "the discovery server (re)starts: its nodes register with it only when they start"
        stale = {a.name for a in actions} - servers
    else:
        reason = "started before the discovery server's last start: not registered with it"
        stale = started_before_servers({e.name: e.started_at if e.running else "" for e in existing}, servers,
                                       server_start)
    return [Action("replace", a.name, reason) if a.verb == "keep" and a.name in stale else a for a in actions]
