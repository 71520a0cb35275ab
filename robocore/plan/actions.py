"""What ``run`` does to each container of a host: create, replace, start, keep or remove (pure).

From the planned container specs and what the host runs now (:class:`Existing`), :func:`decide`
picks one :class:`Action` per container; :func:`with_node_restarts` adds the restarts a discovery
kind whose nodes register only when they start (the ROS 1 master) needs after its server restarts.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from robocore.plan.containers import ROLE_DISCOVERY, ContainerSpec


@dataclass(frozen=True)
class Existing:
    """A managed container found on a host."""

    name: str
    spec_hash: str | None
    image_id: str
    running: bool
    role: str


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


def with_node_restarts(actions: Sequence[Action], specs: Sequence[ContainerSpec], *, register_once: bool,
                       elsewhere: bool = False) -> list[Action]:
    """``actions`` with every kept component replaced when a discovery server (re)starts, on this host or
    ``elsewhere`` (on another host, earlier in the same run), and the kind's nodes register with it only
    when they start (``register_once``: the ROS master forgets its nodes when it restarts, and they never
    tell it again)."""
    servers = {s.name for s in specs if s.role == ROLE_DISCOVERY}
    if not (register_once and (elsewhere or servers_started(actions, specs))):
        return list(actions)
    reason = "the discovery server (re)starts: its nodes register with it only when they start"
    return [Action("replace", a.name, reason) if a.verb == "keep" and a.name not in servers else a for a in actions]
