"""Docker's API through the OpenSSH client: each HTTP connection is ``ssh HOST docker system dial-stdio``.

This is how the docker CLI reaches ``ssh://`` hosts. It reads the same ssh configuration as every
other robocore step (keys, agent, known_hosts, ProxyJump, certificates: whatever OpenSSH supports)
and shares one multiplexed connection per host with sync and connect (``ControlMaster``, see
:mod:`robocore.adapters.ssh`), so a Docker connection opened right after a sync costs one ssh
session, not a new handshake.

The ssh child talks through one end of a ``socketpair``; urllib3 gets the other end, a real
socket, so request timeouts, ``select`` and docker-py's raw streams (logs ``-f``) work unchanged.
"""

from __future__ import annotations

import functools
import socket
import subprocess
from collections.abc import Sequence
from typing import Any

import urllib3.connection
import urllib3.connectionpool

#: Open connections kept per host (sshd allows 10 sessions per connection by default).
POOL_SIZE = 4


class _DialSocket:
    """Our end of the socketpair; ``makefile`` marks its files with ``channel`` as docker-py expects
    of ssh connections when it takes over a response's raw stream."""

    def __init__(self, sock: socket.socket) -> None:
        self._sock = sock

    def makefile(self, *args: Any, **kwargs: Any) -> Any:
        handle = self._sock.makefile(*args, **kwargs)
        handle.channel = self._sock
        return handle

    def __getattr__(self, name: str) -> Any:
        return getattr(self._sock, name)


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
        self.sock = _DialSocket(ours)

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


def attach(client: Any, argv: Sequence[str], timeout: float) -> None:
    """Route every request of a docker-py client made for an ``ssh://`` URL through ``argv``.

    The client must have been created with ``use_ssh_client=True`` (so that docker-py opens no
    connection of its own); its adapter's pools are replaced by one :class:`DialStdioPool`.
    """
    adapter = client.api._custom_adapter
    pool = DialStdioPool(argv, timeout)
    adapter.get_connection = functools.partial(_the_pool, pool)
    adapter.close = functools.partial(_close_pool, pool, adapter.close)


def _the_pool(pool: DialStdioPool, *args: Any, **kwargs: Any) -> DialStdioPool:
    return pool


def _close_pool(pool: DialStdioPool, close: Any) -> None:
    pool.close()
    close()
