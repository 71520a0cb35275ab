"""What the health gate leaves in a robot's service labels once it has decided: its verdict, its reason in words, and
the ROS graph its probe saw (:mod:`robocore.plan.gate_graph`). ``fleet rollout`` and ``fleet rollback`` write it;
``fleet status`` and ``fleet page`` read it from the manager, so they say why, and what was live, from any machine.

A label-only update restarts nothing. The verdict and reason go on every service of the robot (each service's row
reads its own); the graph, up to 2 KB, goes on the first one only, so the manager keeps one copy per robot. Updating
a service to a release replaces its labels, so a robot whose last gate ran no probe (no nodes or topics to check,
offline, or a crash first) has no graph recorded rather than an older release's.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

from robocore.adapters import swarm
from robocore.commands.fleet_swarm import now
from robocore.plan import gate_graph
from robocore.plan import swarm_services as plan

if TYPE_CHECKING:
    import docker


def record_gate(client: docker.DockerClient, specs: Sequence[plan.ServiceSpec], health: str, reason: str,
                verdict: Mapping[str, object] | None = None) -> None:
    """Record the gate's ``health`` verdict and ``reason`` in the labels of a robot's ``specs``, and the graph in
    the probe's ``verdict`` (None when no probe ran or it printed none) with the release the specs target."""
    release = dict(specs[0].labels).get(plan.LABEL_RELEASE, "") if specs else ""
    seen = gate_graph.from_verdict(verdict, release, now())
    for index, spec in enumerate(specs):
        labels = {plan.LABEL_HEALTH: health, plan.LABEL_REASON: reason}
        if index == 0 and seen is not None:
            labels[gate_graph.LABEL_SEEN] = gate_graph.to_label(seen)
        swarm.set_labels(client, spec.name, labels)
