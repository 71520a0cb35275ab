"""docker-py clients, one per host: the only place that opens a Docker connection.

Local hosts use this machine's socket (``DOCKER_HOST`` honoured). Remote access
(ssh, tls, tcp) is added by the deploy work (issue #4).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from robocore.config.model import DockerAccess, Host
from robocore.errors import DockerError

if TYPE_CHECKING:
    import docker


def local_client(timeout: int = 120) -> docker.DockerClient:
    """A client of this machine's Docker daemon, or a DockerError saying why not."""
    import docker
    from docker.errors import DockerException

    try:
        client = docker.from_env(timeout=timeout)
        client.ping()
    except DockerException as exc:
        raise DockerError(
            f"cannot reach the local Docker daemon: {exc}",
            hint="is Docker running, and may this user use it (docker group)?",
        ) from None
    return client


def client_for(host: Host, timeout: int = 120) -> docker.DockerClient:
    """A client of ``host``'s Docker daemon."""
    if host.access is DockerAccess.local:
        return local_client(timeout)
    raise DockerError(f"host {host.name}: docker access {host.access.value!r} is not implemented yet")
