"""A component's robot.yaml ``resources`` as each engine says it: Docker (``run``, compose files), Swarm services and
Kubernetes pods (pure).

| robot.yaml | Docker (``run``, compose) | Swarm service | Kubernetes container / pod |
| --- | --- | --- | --- |
| ``limits.cpu`` | ``--cpus`` | ``Limits.NanoCPUs`` | ``limits.cpu`` |
| ``limits.memory`` | ``--memory`` | ``Limits.MemoryBytes`` | ``limits.memory`` |
| ``requests.cpu`` | ``--cpu-shares`` (1024 a core) | ``Reservations.NanoCPUs`` | ``requests.cpu`` |
| ``requests.memory`` | ``--memory-reservation`` | ``Reservations.MemoryBytes`` | ``requests.memory`` |
| ``priority: critical`` | ``--oom-score-adj -900`` | not carried (1) | ``priorityClassName: system-node-critical`` |

(1) docker-py's service spec has no OOM score.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from robocore.config.resources import Resources

#: Docker's OOM score adjustment of a critical component: far below every other process of the host (the kernel
#: kills the highest first), above -1000, which would make it unkillable.
CRITICAL_OOM_SCORE = -900
#: The priority class of a critical component's pod: Kubernetes' own, evicted last, present in every cluster.
CRITICAL_PRIORITY_CLASS = "system-node-critical"


@dataclass(frozen=True)
class Limits:
    """CPU in millicores and memory in bytes (None: not given), and whether the component is critical."""

    cpu_request: int | None = None
    cpu_limit: int | None = None
    memory_request: int | None = None
    memory_limit: int | None = None
    critical: bool = False

    @classmethod
    def of(cls, resources: Resources | None) -> Limits | None:
        """The limits of a component's ``resources`` (None when it has none)."""
        if resources is None:
            return None
        return cls(cpu_request=resources.requests.cpu, cpu_limit=resources.limits.cpu,
                   memory_request=resources.requests.memory, memory_limit=resources.limits.memory,
                   critical=resources.priority == "critical")

    def as_dict(self) -> dict[str, Any]:
        """Plain data (for a spec's content hash)."""
        return asdict(self)


def docker_kwargs(limits: Limits) -> dict[str, Any]:
    """docker-py ``containers.create`` keyword arguments."""
    out: dict[str, Any] = {}
    if limits.cpu_limit is not None:
        out["nano_cpus"] = limits.cpu_limit * 1_000_000
    if limits.cpu_request is not None:
        out["cpu_shares"] = max(2, limits.cpu_request * 1024 // 1000)
    if limits.memory_limit is not None:
        out["mem_limit"] = limits.memory_limit
    if limits.memory_request is not None:
        out["mem_reservation"] = limits.memory_request
    if limits.critical:
        out["oom_score_adj"] = CRITICAL_OOM_SCORE
    return out


def compose_keys(limits: Limits) -> dict[str, Any]:
    """The compose-file service keys (the same values as ``run``)."""
    out: dict[str, Any] = {k: v for k, v in docker_kwargs(limits).items() if k != "nano_cpus"}
    if limits.cpu_limit is not None:
        out["cpus"] = limits.cpu_limit / 1000
    return out


def swarm_resources(limits: Limits | None) -> dict[str, Any]:
    """docker-py ``docker.types.Resources`` keyword arguments of a service ({} for none)."""
    if limits is None:
        return {}
    out: dict[str, Any] = {}
    if limits.cpu_limit is not None:
        out["cpu_limit"] = limits.cpu_limit * 1_000_000
    if limits.memory_limit is not None:
        out["mem_limit"] = limits.memory_limit
    if limits.cpu_request is not None:
        out["cpu_reservation"] = limits.cpu_request * 1_000_000
    if limits.memory_request is not None:
        out["mem_reservation"] = limits.memory_request
    return out


def pod_resources(limits: Limits) -> dict[str, dict[str, str]]:
    """The container's ``resources`` (Kubernetes quantities: millicores, bytes)."""
    out: dict[str, dict[str, str]] = {}
    for kind, cpu, memory in (("requests", limits.cpu_request, limits.memory_request),
                              ("limits", limits.cpu_limit, limits.memory_limit)):
        amounts = {}
        if cpu is not None:
            amounts["cpu"] = f"{cpu}m"
        if memory is not None:
            amounts["memory"] = str(memory)
        if amounts:
            out[kind] = amounts
    return out
