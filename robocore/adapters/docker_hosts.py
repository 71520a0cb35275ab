"""docker-py clients, one per host: the only place that opens a Docker connection.

- ``local``: this machine's socket (``DOCKER_HOST`` honoured).
- ``ssh`` (default for remote hosts): the OpenSSH client to ``user@ip:ssh_port``, then ``docker
  system dial-stdio`` on the host, as the docker CLI does, so the daemon never listens on the
  network (:mod:`robocore.adapters.docker_over_ssh`). Keys, known hosts and every other setting
  come from the ssh configuration robocore uses (:mod:`robocore.adapters.ssh`).
- ``tls``: ``https://ip:docker_port`` (default 2376) with the host's client certificate; the
  daemon's certificate is verified against ``ca_cert``.
- ``tcp``: plain ``tcp://ip:docker_port`` (default 2375), only with ``insecure: true``, and
  with a warning each time.

Connecting fails with a HostError naming the host within about ``CONNECT_TIMEOUT`` seconds when the
host is down, so one dead robot never stalls work on the others.

An ssh connection can be opened ahead of time (:func:`prefetch`): ``build sync run`` starts run's
connections while it builds and syncs, and :func:`client_for` then takes the open one.
"""

from __future__ import annotations

import subprocess
import threading
from concurrent.futures import Future
from pathlib import Path
from typing import TYPE_CHECKING, Any

from robocore.adapters.ssh import CONNECT_TIMEOUT
from robocore.config.model import DockerAccess, Host, TlsFiles
from robocore.errors import DockerError, HostError
from robocore.plan.addresses import bare, url_host

if TYPE_CHECKING:
    import docker

#: API version used before the real one is negotiated (Docker 20.10 speaks 1.41).
_BOOTSTRAP_API = "1.41"


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
    A connection :func:`prefetch` opened with the same settings is taken (or its error raised).
    """
    access = host.access
    if access is DockerAccess.local:
        return local_client(timeout)
    if access is DockerAccess.ssh:
        with _prefetch_lock:
            pending = _prefetched.pop(_prefetch_key(host, timeout, connect_timeout), None)
        if pending is not None:
            return pending.result()
        return ssh_client(host, timeout, connect_timeout)
    if access is DockerAccess.tls:
        return _tls_client(host, timeout, connect_timeout, project_root or Path.cwd())
    return _tcp_client(host, timeout, connect_timeout)


_prefetched: dict[tuple[str, str, int, int, int], Future[docker.DockerClient]] = {}
_prefetch_lock = threading.Lock()


def _prefetch_key(host: Host, timeout: int, connect_timeout: int) -> tuple[str, str, int, int, int]:
    return (host.user, host.ip, host.ssh_port, timeout, connect_timeout)


def load_client_modules() -> None:
    """Import docker-py, requests and the ssh transport in the calling thread.

    Threads that import a package with import cycles (requests) at the same moment can find it half
    initialized ("cannot import name ... from partially initialized module"): code that starts threads
    which make Docker clients calls this first.
    """
    import docker  # noqa: F401

    from robocore.adapters import docker_over_ssh  # noqa: F401


def prefetch(host: Host, timeout: int = 120, *, connect_timeout: int = CONNECT_TIMEOUT) -> None:
    """Start connecting to an ssh host's daemon in the background, for a later :func:`client_for` with the
    same settings. Nothing is reported here: the error, if any, is raised by that call. Other kinds of
    access, and a host already being fetched, are left alone."""
    if host.access is not DockerAccess.ssh:
        return
    key = _prefetch_key(host, timeout, connect_timeout)
    with _prefetch_lock:
        if key in _prefetched:
            return
        pending: Future[docker.DockerClient] = Future()
        _prefetched[key] = pending
    load_client_modules()

    def work() -> None:
        try:
            pending.set_result(ssh_client(host, timeout, connect_timeout))
        except BaseException as exc:  # handed to whoever takes the connection
            pending.set_exception(exc)

    # a daemon thread: a command that ends early (a failed build) does not wait for a connection it never used
    threading.Thread(target=work, name=f"robocore-prefetch-{host.name}", daemon=True).start()


def describe(host: Host) -> str:
    """How ``host``'s daemon is reached, for messages and dry runs."""
    access = host.access
    if access is DockerAccess.local:
        return "local socket"
    if access is DockerAccess.ssh:
        return f"ssh://{host.user}@{url_host(host.ip, host.ssh_port)}"
    if access is DockerAccess.tls:
        return f"https://{url_host(host.ip, host.docker_port or 2376)} (tls)"
    return f"tcp://{url_host(host.ip, host.docker_port or 2375)} (insecure)"


#: What to do when a host's daemon cannot be reached and nothing more specific is known.
_CHECK_HOST = "is the host up? `robocore doctor` checks ssh, Docker and disk on every host"


def _cannot_reach(host: Host, detail: str, hint: str | None = _CHECK_HOST) -> HostError:
    return HostError(f"host {host.name}: cannot reach its Docker daemon at {describe(host)}: {detail}", hint=hint)


def _unreachable(host: Host, exc: BaseException) -> HostError:
    detail = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return _cannot_reach(host, detail)


def ssh_client(host: Host, timeout: int, connect_timeout: int) -> docker.DockerClient:
    """A client whose requests run ``docker system dial-stdio`` on the host over ssh.

    The first request asks for the daemon's API version. If it fails, ``docker version`` over ssh
    says why in ssh's or docker's own words (or gives the version an older daemon needs).
    """
    import time

    from robocore.adapters import ssh

    started = time.monotonic()
    try:
        return _dial(host, timeout, connect_timeout, None)
    except Exception as exc:
        if not is_connection_error(exc):
            raise
        first = exc
    if time.monotonic() - started >= connect_timeout - 0.5:  # ssh gave up connecting: asking again would too
        raise _cannot_reach(host, f"no answer within {connect_timeout} s")
    check = ["docker", "version", "--format", "{{.Server.APIVersion}}"]
    try:
        proc = ssh.run(host, check, timeout=2 * connect_timeout + 10, check=False, connect_timeout=connect_timeout)
    except HostError as exc:
        raise _cannot_reach(host, exc.message, exc.hint) from None
    if proc.returncode != 0:
        raise _ssh_refused(host, proc, check)
    version = proc.stdout.decode(errors="replace").strip()
    try:
        return _dial(host, timeout, connect_timeout, version or None)
    except Exception as exc:
        if is_connection_error(exc):
            raise _unreachable(host, first) from None
        raise


def _dial(host: Host, timeout: int, connect_timeout: int, version: str | None) -> docker.DockerClient:
    from robocore.adapters import docker_over_ssh, ssh

    ssh.ensure_control_dir()
    client = docker_over_ssh.client(ssh.ssh_argv(host, ["docker", "system", "dial-stdio"],
                                                 connect_timeout=connect_timeout),
                                    timeout=timeout, version=version or _BOOTSTRAP_API)
    api: Any = client.api
    if version is None:
        api._version = api._retrieve_server_version()
    return client


def is_connection_error(exc: BaseException) -> bool:
    """True for errors of the connection to a daemon (socket, docker-py, requests, urllib3), as opposed to bugs."""
    return isinstance(exc, OSError) or type(exc).__module__.split(".")[0] in {"docker", "requests", "urllib3"}


def _ssh_refused(host: Host, proc: subprocess.CompletedProcess[bytes], remote: list[str]) -> HostError:
    from robocore.adapters import ssh

    text = proc.stderr.decode(errors="replace")
    if proc.returncode == 255:
        return _cannot_reach(host, ssh.describe_failure(proc, remote), ssh.failure_hint(proc))
    if proc.returncode == 127 or "command not found" in text or "docker: not found" in text:
        return _cannot_reach(host, "the docker command is not installed there",
                             f"install Docker on {host.name} (Debian: apt-get install docker.io)")
    if "permission denied" in text.lower():
        return _cannot_reach(host, f"user {host.user} may not use Docker there",
                             f"add {host.user} to the docker group on {host.name} (usermod -aG docker {host.user})")
    return _cannot_reach(host, ssh.describe_failure(proc, remote),
                         f"is the Docker daemon running on {host.name}? (systemctl status docker)")


def tls_files(host: Host, root: Path) -> TlsFiles:
    """The TLS files of ``host`` as paths on this machine: ``~`` expanded, relative paths taken from the project
    folder ``root``."""
    if host.tls is None:
        raise HostError(f"host {host.name}: docker: tls needs tls: {{ca_cert, client_cert, client_key}} in robot.yaml")

    def resolve(value: str) -> str:
        path = Path(value).expanduser()
        return str(path if path.is_absolute() else root / path)

    return TlsFiles(ca_cert=resolve(host.tls.ca_cert), client_cert=resolve(host.tls.client_cert),
                    client_key=resolve(host.tls.client_key))


def _tls_client(host: Host, timeout: int, connect_timeout: int, root: Path) -> docker.DockerClient:
    from docker.tls import TLSConfig

    files = tls_files(host, root)
    tls = TLSConfig(client_cert=(files.client_cert, files.client_key), ca_cert=files.ca_cert, verify=True)
    return _tcp_like(host, f"https://{url_host(host.ip, host.docker_port or 2376)}", timeout, connect_timeout, tls)


def _tcp_client(host: Host, timeout: int, connect_timeout: int) -> docker.DockerClient:
    if not host.insecure:
        raise HostError(f"host {host.name}: docker: tcp is plain, unauthenticated TCP",
                        hint="use ssh or tls, or set insecure: true on this host if the network is trusted")
    from rich.markup import escape

    from robocore.ui import console

    console().print(f"[yellow]warning:[/] host {host.name}: Docker over plain TCP ({escape(describe(host))}): "
                    "anyone on the network can control this daemon; prefer ssh or tls")
    return _tcp_like(host, f"tcp://{url_host(host.ip, host.docker_port or 2375)}", timeout, connect_timeout, False)


def _tcp_like(host: Host, base_url: str, timeout: int, connect_timeout: int, tls: Any) -> docker.DockerClient:
    import socket

    import docker

    port = int(base_url.rsplit(":", 1)[1])
    try:
        # Fail fast on a dead host: requests would otherwise wait for the full API timeout.
        socket.create_connection((bare(host.ip), port), timeout=connect_timeout).close()
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
