"""Debian's docker-registry on this machine's loopback, reachable as the same ``127.0.0.1:PORT`` on every
robot host of a fleet through an ssh reverse tunnel (a loopback registry needs no TLS in dockerd).

The same set-up as test_multihost's ``registry`` fixture, as a context manager for other suites.
"""

from __future__ import annotations

import contextlib
import json
import shutil
import subprocess
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from deploy_helpers import free_tcp_port, wait_for

if TYPE_CHECKING:
    from robot_host.hosts import RobotFleet


@contextlib.contextmanager
def serve_registry(fleet: RobotFleet | None, folder: Path) -> Iterator[str]:
    """Serve a registry (its data under ``folder``) to this machine and to ``fleet``'s hosts (None: to this machine
    only); ``127.0.0.1:PORT``."""
    binary = shutil.which("docker-registry")
    assert binary, "the release tests need Debian's docker-registry package (apt-get install docker-registry)"
    port = free_tcp_port()
    config = folder / "config.yml"
    config.write_text(f"version: 0.1\nstorage:\n  filesystem:\n    rootdirectory: {folder / 'data'}\n"
                      f"http:\n  addr: 127.0.0.1:{port}\nlog:\n  level: warn\n")
    server = subprocess.Popen([binary, "serve", str(config)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    def serving() -> bool:
        with contextlib.suppress(OSError), urllib.request.urlopen(f"http://127.0.0.1:{port}/v2/", timeout=2):
            return True
        return False

    try:
        assert wait_for(serving, 30, interval=0.2), f"docker-registry did not answer on 127.0.0.1:{port}"
        with contextlib.ExitStack() as stack:
            if fleet is not None:
                stack.enter_context(registry_tunnels(fleet, f"127.0.0.1:{port}"))
            yield f"127.0.0.1:{port}"
    finally:
        server.kill()
        server.wait()


@contextlib.contextmanager
def registry_tunnels(fleet: RobotFleet, address: str) -> Iterator[None]:
    """Make the registry at ``address`` (``127.0.0.1:PORT`` on this machine) the same address on every host of
    ``fleet``: one ssh reverse tunnel each, up when this returns, closed afterwards."""
    port = address.rsplit(":", 1)[1]
    tunnels = []
    try:
        for host in fleet.hosts:
            tunnels.append(subprocess.Popen(
                ["ssh", "-F", str(fleet.ssh_config), "-N", "-o", "ExitOnForwardFailure=yes",
                 "-R", f"{port}:127.0.0.1:{port}", f"root@{host.ip}"], stdin=subprocess.DEVNULL))
        probe = ["sh", "-c", '"$@" && echo up || true', "sh", "bash", "-c", f"exec 3<>/dev/tcp/127.0.0.1/{port}"]
        for host in fleet.hosts:
            assert wait_for(lambda h=host: h.ssh(fleet, *probe).strip() == "up", 20, interval=0.3), \
                f"registry tunnel to {host.name} did not come up"
        yield
    finally:
        for tunnel in tunnels:
            tunnel.kill()
            tunnel.wait()


def manifest(registry: str, repo: str, reference: str) -> dict[str, Any]:
    """The manifest (or manifest list) the registry serves for ``repo:reference``."""
    accept = ", ".join(["application/vnd.docker.distribution.manifest.list.v2+json",
                        "application/vnd.oci.image.index.v1+json",
                        "application/vnd.docker.distribution.manifest.v2+json"])
    request = urllib.request.Request(f"http://{registry}/v2/{repo}/manifests/{reference}", headers={"Accept": accept})
    with urllib.request.urlopen(request, timeout=10) as resp:
        return dict(json.loads(resp.read()))
