"""Docker's API through the OpenSSH client: each HTTP connection is ``ssh HOST docker system dial-stdio``.

This is how the docker CLI reaches ``ssh://`` hosts. It reads the same ssh configuration as every
other robocore step (keys, agent, known_hosts, ProxyJump, certificates: whatever OpenSSH supports)
and shares one multiplexed connection per host with sync and connect (``ControlMaster``, see
:mod:`robocore.adapters.ssh`), so a Docker connection opened right after a sync costs one ssh
session, not a new handshake.

The ssh child talks through one end of a ``socketpair``; urllib3 gets the other end, a real
socket, so request timeouts, ``select`` and docker-py's raw streams (logs ``-f``) work as they do
on the local Unix socket. docker-py's own ``ssh://`` transport is not used, so paramiko (which
it would import) is not needed.
"""

from __future__ import annotations

import socket
import subprocess
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import requests.adapters
import urllib3.connection
import urllib3.connectionpool

if TYPE_CHECKING:
    import docker

#: Open connections kept per host (sshd allows 10 sessions per connection by default).
POOL_SIZE = 4


class DialStdioConnection(urllib3.connection.HTTPConnection):
    """An HTTP connection to the Docker daemon of a host, through an ssh child process."""

    def __init__(self, argv: Sequence[str], timeout: float) -> None:
        super().__init__("localhost", timeout=timeout)
        self._argv = list(argv)
        self._timeout = timeout
        self._proc: subprocess.Popen[bytes] | None = None

    def connect(self) -> None:
        """Start the ssh child on one end of a socketpair; keep the other."""
        ours, theirs = socket.socketpair()
        try:
            # its own session: Ctrl-C reaches robocore, which then closes the connection cleanly
            self._proc = subprocess.Popen(self._argv, stdin=theirs.fileno(), stdout=theirs.fileno(),
                                          stderr=subprocess.DEVNULL,
                                          start_new_session=True)
        except OSError:
            ours.close()
            raise
        finally:
            theirs.close()
        ours.settimeout(self._timeout)
        self.sock = ours

    def close(self) -> None:
        """Close the socket; the ssh child sees end-of-file and exits (or is stopped)."""
        super().close()
        proc, self._proc = self._proc, None
        if proc is None:
            return
        try:
            proc.wait(timeout=2)
        except subprocess.TimeoutExpired:
            proc.terminate()
            try:
                proc.wait(timeout=2)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


class DialStdioPool(urllib3.connectionpool.HTTPConnectionPool):
    """A pool of :class:`DialStdioConnection` to one host."""

    def __init__(self, argv: Sequence[str], timeout: float, maxsize: int = POOL_SIZE) -> None:
        super().__init__("localhost", timeout=timeout, maxsize=maxsize, block=True)
        self._argv = list(argv)
        self._timeout = timeout

    def _new_conn(self) -> urllib3.connection.HTTPConnection:
        return DialStdioConnection(self._argv, self._timeout)


class DialStdioAdapter(requests.adapters.HTTPAdapter):
    """The requests adapter of a docker-py client: every request goes to one :class:`DialStdioPool`."""

    def __init__(self, pool: DialStdioPool) -> None:
        super().__init__()
        self._pool = pool

    def get_connection(self, url: str, proxies: Any = None) -> DialStdioPool:  # type: ignore[override]
        """The pool, whatever the URL (requests < 2.32.2)."""
        return self._pool

    def get_connection_with_tls_context(self, request: Any, verify: Any, proxies: Any = None,
                                        cert: Any = None) -> DialStdioPool:
        """The pool, whatever the request (requests >= 2.32.2)."""
        return self._pool

    def request_url(self, request: Any, proxies: Any) -> str:
        """Only the path: the pool knows where it goes (and proxies do not apply)."""
        return str(request.path_url)

    def close(self) -> None:
        """Close the pool's connections: their ssh children exit."""
        super().close()
        self._pool.close()


def client(argv: Sequence[str], *, timeout: float, version: str) -> docker.DockerClient:
    """A docker-py client whose requests all go through ``argv`` (``ssh ... docker system dial-stdio``).

    It is made as a client of a local Unix socket that is never opened: that adapter is replaced
    by a :class:`DialStdioAdapter` before any request, and docker-py reads raw streams from our
    socket as it does from a Unix socket.
    """
    import docker

    made = docker.DockerClient(base_url="unix:///robocore-dial-stdio.sock", version=version, timeout=int(timeout))
    adapter = DialStdioAdapter(DialStdioPool(argv, timeout))
    api: Any = made.api
    api.mount("http+docker://", adapter)
    api._custom_adapter = adapter  # docker-py's fallback for URLs no mount matches
    return made
