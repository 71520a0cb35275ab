"""Docker Swarm through docker-py, for reading what one service's tasks do: their logs as a stream and the running
task's container, both through the manager (beside :mod:`robocore.adapters.swarm`, which changes the swarm).

Swarm's API lets a manager stream a service's logs from the nodes (``/services/{id}/logs``: each node's agent
sends its tasks' output up), but has no exec or attach for a task: a shell in a task's container needs the daemon
of the node that runs it (see docs/fleets.md, "Logs and a shell").
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

from robocore.adapters.swarm import swarm_errors

if TYPE_CHECKING:
    import docker


def log_chunks(client: docker.DockerClient, service: str, *, follow: bool, tail: int) -> Iterator[bytes]:
    """The output (stdout and stderr) of ``service``'s tasks as the manager streams it, the last ``tail`` lines of
    each task first; with ``follow``, live until the stream is closed. The chunks are not cut at line ends."""
    with swarm_errors(f"docker service logs {service}"):
        stream = client.api.service_logs(service, stdout=True, stderr=True, follow=follow, tail=str(tail),
                                           is_tty=False)
    try:
        yield from stream
    except Exception as exc:  # the stream broke (the manager went away): one line, as the other calls
        if type(exc).__module__.split(".")[0] in {"docker", "requests", "urllib3"}:
            from robocore.errors import DockerError

            raise DockerError(f"docker service logs {service}: the stream ended: {exc}") from None
        raise


@dataclass(frozen=True)
class RunningTask:
    """The task of a service that runs now: its node, its container, and the command its container was started with
    (the service's entrypoint override; empty when the image's own entrypoint is used)."""

    node_id: str
    container: str
    entrypoint: tuple[str, ...]


def running_task(client: docker.DockerClient, service: str) -> RunningTask | None:
    """The task of ``service`` that runs now and is meant to (None when none does), read from the manager."""
    from docker.errors import NotFound

    with swarm_errors(f"docker service ps {service}"):
        try:
            found = client.api.tasks(filters={"service": service, "desired-state": "running"})  # type: ignore[no-untyped-call]
        except NotFound:
            return None
    for attrs in found:
        status = attrs.get("Status") or {}
        container = str((status.get("ContainerStatus") or {}).get("ContainerID") or "")
        if status.get("State") == "running" and container:
            spec = (attrs.get("Spec") or {}).get("ContainerSpec") or {}
            return RunningTask(node_id=str(attrs.get("NodeID") or ""), container=container,
                               entrypoint=tuple(str(a) for a in spec.get("Command") or ()))
    return None
