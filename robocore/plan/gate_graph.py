"""The ROS graph the health gate saw on a robot, as one bounded service label (pure: the probe's verdict in, a label
out, and back).

The gate's probe prints what it saw of the robot's graph (``nodes``, and the topics it ``heard``) in its verdict.
``fleet rollout`` and ``fleet rollback`` keep it in a label of one of the robot's services beside the verdict and
its reason (:mod:`robocore.commands.fleet_gate_record`), so ``fleet status --json`` and ``fleet page`` show, from any
machine that reaches the manager, which live nodes the last gate saw. The label is bounded (:data:`MAX_BYTES`): a
robot with a huge graph keeps its first names and says how many it left out, rather than growing every look at the
fleet. A label that does not parse (an older robocore's, or one set by hand) reads as nothing seen.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

#: The service label that holds the graph the last gate saw (JSON, see :func:`to_label`).
LABEL_SEEN = "dev.robocore.fleet.seen"
#: The most bytes the label may hold: a robot's usual graph (tens of nodes and topics of ~30 characters) fits
#: whole, and 1000 robots' labels stay ~2 MB in the manager and in each look of ``fleet status`` or the page.
MAX_BYTES = 2048
#: The most characters kept of one name (a ROS name that long is a mistake or a hostile probe's output).
MAX_NAME = 200


@dataclass(frozen=True)
class Seen:
    """What the last gate's probe saw on a robot: the nodes in its graph and the topics it heard, on which release
    and when; ``omitted`` names were left out to keep the record within :data:`MAX_BYTES`."""

    release: str
    at: str  # UTC, ISO 8601 to the second
    nodes: tuple[str, ...] = ()
    heard: tuple[str, ...] = ()
    omitted: int = 0


def _names(value: object) -> list[str]:
    """The strings of a verdict's list (anything else in it dropped), each cut to :data:`MAX_NAME` characters."""
    if not isinstance(value, list):
        return []
    return sorted({item[:MAX_NAME] for item in value if isinstance(item, str) and item})


def from_verdict(verdict: Mapping[str, object] | None, release: str, at: str) -> Seen | None:
    """The graph in a probe's ``verdict`` (None when there is no verdict, or it names no node and heard nothing),
    bounded as its label will be."""
    if verdict is None:
        return None
    nodes, heard = _names(verdict.get("nodes")), _names(verdict.get("heard"))
    if not nodes and not heard:
        return None
    return _bounded(release, at, nodes, heard)


def _bounded(release: str, at: str, nodes: list[str], heard: list[str]) -> Seen:
    """The nodes first, then the topics, as many as the label's bytes allow (each name costs its JSON text and a
    comma; the frame is counted with the largest ``omitted`` it could hold)."""
    frame = len(to_label(Seen(release, at, omitted=len(nodes) + len(heard))))
    budget = MAX_BYTES - frame
    kept: dict[str, list[str]] = {"nodes": [], "heard": []}
    omitted = 0
    for key, names in (("nodes", nodes), ("heard", heard)):
        for name in names:
            cost = len(json.dumps(name)) + 1
            if cost <= budget:
                kept[key].append(name)
                budget -= cost
            else:
                omitted += 1
    return Seen(release, at, tuple(kept["nodes"]), tuple(kept["heard"]), omitted)


def to_label(seen: Seen) -> str:
    """``seen`` as its label's value: compact JSON (ASCII: every byte counted is one character)."""
    return json.dumps({"release": seen.release, "at": seen.at, "nodes": list(seen.nodes), "heard": list(seen.heard),
                       "omitted": seen.omitted}, separators=(",", ":"))


def from_label(text: str) -> Seen | None:
    """The record a label holds; None when it is empty, too long or not a record of this shape."""
    if not text or len(text) > MAX_BYTES:
        return None
    try:
        value = json.loads(text)
    except ValueError:
        return None
    if not isinstance(value, dict):
        return None
    release, at, omitted = value.get("release"), value.get("at"), value.get("omitted", 0)
    if not isinstance(release, str) or not isinstance(at, str) or not isinstance(omitted, int) or omitted < 0:
        return None
    return Seen(release, at, tuple(_names(value.get("nodes"))), tuple(_names(value.get("heard"))), omitted)


def latest(labels: Iterable[Mapping[str, str]]) -> Seen | None:
    """The newest record among a robot's services' ``labels`` (one service holds it; a stale copy on another, if
    any, is older)."""
    found = [seen for one in labels if (seen := from_label(one.get(LABEL_SEEN, ""))) is not None]
    return max(found, key=lambda seen: seen.at, default=None)
