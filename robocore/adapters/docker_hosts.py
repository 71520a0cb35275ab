"""docker-py clients, one per host: the only place that opens a Docker connection.

- ``local``: this machine's socket (``DOCKER_HOST`` honoured).
- ``ssh`` (default for remote hosts): paramiko to ``user@ip:ssh_port``, then ``docker system
  dial-stdio`` on the host, so the daemon never listens on the network. Keys and known hosts come
  from the ssh_config file robocore uses (:mod:`robocore.adapters.ssh`).
- ``tls``: ``https://ip:docker_port`` (default 2376) with the host's client certificate; the
  daemon's certificate is verified against ``ca_cert``.
- ``tcp``: plain ``tcp://ip:docker_port`` (default 2375), only with ``insecure: true``, and
  with a warning each time.

Connecting fails with a HostError naming the host within about ``CONNECT_TIMEOUT`` seconds when the
host is down, so one dead robot never stalls work on the others.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import TYPE_CHECKING, Any

from robocore.adapters.ssh import CONNECT_TIMEOUT, paramiko_settings
from robocore.config.model import DockerAccess, Host
from robocore.errors import DockerError, HostError

if TYPE_CHECKING:
    import docker

#: API version used before the real one is negotiated (Docker 20.10 speaks 1.41).
_BOOTSTRAP_API = "1.41"
#: Open ssh channels kept per host (sshd allows 10 sessions per connection by default).
_SSH_POOL = 4


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


def client_for(host: Host, timeout: int = 120, *, project_root: Path | None = None,
               connect_timeout: int = CONNECT_TIMEOUT) -> docker.DockerClient:
    """A client of ``host``'s Docker daemon (pinged), or a HostError naming the host.

    ``timeout`` bounds each API call; ``connect_timeout`` bounds reaching the host.
    ``project_root`` resolves relative TLS file paths (default: the current folder).
    """
    access = host.access
    if access is DockerAccess.local:
        return local_client(timeout)
    if access is DockerAccess.ssh:
        return _ssh_client(host, timeout, connect_timeout)
    if access is DockerAccess.tls:
        return _tls_client(host, timeout, connect_timeout, project_root or Path.cwd())
    return _tcp_client(host, timeout, connect_timeout)


def describe(host: Host) -> str:
    """How ``host``'s daemon is reached, for messages and dry runs."""
    access = host.access
    if access is DockerAccess.local:
        return "local socket"
    if access is DockerAccess.ssh:
        return f"ssh://{host.user}@{host.ip}:{host.ssh_port}"
    if access is DockerAccess.tls:
        return f"https://{host.ip}:{host.docker_port or 2376} (tls)"
    return f"tcp://{host.ip}:{host.docker_port or 2375} (insecure)"


def _unreachable(host: Host, exc: BaseException) -> HostError:
    detail = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    hint = "is the host up? `robocore doctor` checks ssh, Docker and disk on every host"
    if "known_hosts" in detail:
        hint = f"check the host key, then add it: ssh-keyscan -p {host.ssh_port} {host.ip} >> ~/.ssh/known_hosts"
    elif type(exc).__name__ == "AuthenticationException":
        hint = f"robocore uses ssh keys only: ssh-copy-id -p {host.ssh_port} {host.user}@{host.ip}"
    elif "dial-stdio" in detail or "docker: not found" in detail:
        hint = f"install the docker CLI on {host.name} (Debian: apt-get install docker.io)"
    return HostError(f"host {host.name}: cannot reach its Docker daemon at {describe(host)}: {detail}", hint=hint)


def _ssh_client(host: Host, timeout: int, connect_timeout: int) -> docker.DockerClient:
    import docker
    import paramiko

    settings = paramiko_settings(host, connect_timeout=connect_timeout)
    base_url = f"ssh://{host.user}@{host.ip}:{host.ssh_port}"
    try:
        ssh = paramiko.SSHClient()
        ssh.load_system_host_keys()
        for path in settings.known_hosts:
            if Path(path).is_file():
                ssh.load_host_keys(path)
        ssh.set_missing_host_key_policy(paramiko.RejectPolicy() if settings.strict else paramiko.AutoAddPolicy())
        ssh.connect(**settings.params)
        transport = ssh.get_transport()
        if transport is not None:
            transport.set_keepalive(5)
        # use_ssh_client=True only stops docker-py from opening its own paramiko connection (which
        # has no timeouts); its adapter then gets ours before any request is made.
        client = docker.DockerClient(base_url=base_url, version=_BOOTSTRAP_API, timeout=timeout,
                                     use_ssh_client=True)
        api: Any = client.api
        adapter: Any = api._custom_adapter
        adapter.ssh_client = ssh
        adapter.ssh_params = settings.params
        adapter.get_connection = functools.partial(_one_pool, adapter)
        api._version = api._retrieve_server_version()
        client.ping()
    except (OSError, paramiko.SSHException, docker.errors.DockerException) as exc:
        raise _unreachable(host, exc) from None
    except Exception as exc:  # requests/urllib3 wrap socket errors in their own types
        if type(exc).__module__.split(".")[0] in {"requests", "urllib3"}:
            raise _unreachable(host, exc) from None
        raise
    return client


def _one_pool(adapter: Any, url: str, proxies: Any = None) -> Any:
    """docker-py keeps one pool of open ssh channels per request URL, and sshd allows 10 sessions
    per connection (MaxSessions): share one small pool instead."""
    from docker.transport.sshconn import SSHConnectionPool

    with adapter.pools.lock:
        pool = adapter.pools.get("ssh")
        if pool is None:
            if adapter.ssh_client.get_transport() is None:
                adapter.ssh_client.connect(**adapter.ssh_params)
            pool = SSHConnectionPool(ssh_client=adapter.ssh_client, timeout=adapter.timeout,
                                     maxsize=_SSH_POOL, host=adapter.ssh_host)
            adapter.pools["ssh"] = pool
    return pool


def _tls_client(host: Host, timeout: int, connect_timeout: int, root: Path) -> docker.DockerClient:
    from docker.tls import TLSConfig

    if host.tls is None:
        raise HostError(f"host {host.name}: docker: tls needs tls: {{ca_cert, client_cert, client_key}} in robot.yaml")

    def resolve(value: str) -> str:
        path = Path(value).expanduser()
        return str(path if path.is_absolute() else root / path)

    tls = TLSConfig(client_cert=(resolve(host.tls.client_cert), resolve(host.tls.client_key)),
                    ca_cert=resolve(host.tls.ca_cert), verify=True)
    return _tcp_like(host, f"https://{host.ip}:{host.docker_port or 2376}", timeout, connect_timeout, tls)


def _tcp_client(host: Host, timeout: int, connect_timeout: int) -> docker.DockerClient:
    if not host.insecure:
        raise HostError(f"host {host.name}: docker: tcp is plain, unauthenticated TCP",
                        hint="use ssh or tls, or set insecure: true on this host if the network is trusted")
    from robocore.ui import console

    console().print(f"[yellow]warning:[/] host {host.name}: Docker over plain TCP ({describe(host)}): "
                    "anyone on the network can control this daemon; prefer ssh or tls")
    return _tcp_like(host, f"tcp://{host.ip}:{host.docker_port or 2375}", timeout, connect_timeout, False)


def _tcp_like(host: Host, base_url: str, timeout: int, connect_timeout: int, tls: Any) -> docker.DockerClient:
    import socket

    import docker

    port = int(base_url.rsplit(":", 1)[1])
    try:
        # Fail fast on a dead host: requests would otherwise wait for the full API timeout.
        socket.create_connection((host.ip, port), timeout=connect_timeout).close()
        client = docker.DockerClient(base_url=base_url, tls=tls, timeout=timeout, version=_BOOTSTRAP_API)
        api: Any = client.api
        # Not the environment's proxy or CA bundle (REQUESTS_CA_BUNDLE would replace the host's CA).
        api.trust_env = False
        api._version = api._retrieve_server_version()
        client.ping()
    except Exception as exc:
        if isinstance(exc, (OSError, docker.errors.DockerException)) or type(exc).__module__.split(".")[0] in {
            "requests", "urllib3"
        }:
            raise _unreachable(host, exc) from None
        raise
    return client
