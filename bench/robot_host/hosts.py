"""Simulated robot hosts for the integration suites: Docker-in-Docker containers with sshd.

Each host runs Debian's dockerd and sshd (image from :mod:`robot_host.build`) on a private
user-defined bridge network, started with the settings Docker-in-Docker needs (all capabilities but
SYS_RESOURCE, seccomp/apparmor unconfined, /sys/fs/cgroup bind, exec tmpfs on /var/lib/docker;
``--privileged`` does not work on these machines). A fresh ed25519 key is generated per fleet,
its public half injected through ``AUTHORIZED_KEY``, and the host keys are collected with
ssh-keyscan into a private known_hosts. ``ROBOCORE_SSH_CONFIG`` points robocore at that config,
so robocore reaches each host exactly as it would a real robot: ``ssh://root@<ip>``.

The suites get fleets from conftest's ``robot_fleets`` and ``fleet`` fixtures, which remove them.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import tempfile
import time
import uuid
from collections.abc import Callable, Collection
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from docker.types import Mount
from testcontainers.core.container import DockerContainer
from testcontainers.core.network import Network

from robot_host.build import ensure_image
from robot_host.polling import wait_for

os.environ.setdefault("TESTCONTAINERS_RYUK_DISABLED", "true")

PREFIX = "robocore-it-host"


@dataclass
class RobotHost:
    """One running simulated robot."""

    name: str
    container: DockerContainer
    ip: str

    def ssh(self, fleet: RobotFleet, *argv: str, check: bool = True, timeout: float = 60) -> str:
        """Run argv on the host over ssh (quoted), return stdout."""
        import shlex

        proc = subprocess.run(
            ["ssh", "-F", str(fleet.ssh_config), f"root@{self.ip}", "--", shlex.join(argv)],
            capture_output=True, text=True, timeout=timeout,
        )
        if check and proc.returncode != 0:
            raise AssertionError(f"ssh {self.name} {argv} exited {proc.returncode}: {proc.stderr}")
        return proc.stdout

    def docker(self, fleet: RobotFleet) -> Any:
        """A new docker-py client of the host's inner daemon, which the caller closes (for scripts such as
        bench/deploy.py; the suites use the fleet's own clients, :meth:`RobotFleet.client`)."""
        from robocore.adapters.docker_hosts import client_for
        from robocore.config.model import Host

        return client_for(Host(name=self.name, ip=self.ip), timeout=600)


class RobotFleet:
    """``count`` robot hosts on one private network: :meth:`start` them, :meth:`close` removes everything.

    The suites get fleets from conftest's fixtures; a script uses a fleet as a context manager.
    """

    def __init__(self, count: int = 2, tag: str = "", *, env: list[dict[str, str]] | None = None,
                 setup: Callable[[RobotHost], None] | None = None, disks: Collection[int] = ()) -> None:
        """``env[i]``: extra environment of host i (e.g. DOCKERD_ARGS); ``setup(host)`` runs once its
        address is known and before waiting for its daemon (e.g. to put TLS certificates in); ``disks``: the
        hosts that can be restarted or lose their power (:meth:`power_off`, :meth:`power_on`) as a machine can: their
        /var/lib/docker is a volume of their own (a disk, kept across a restart, where the others' is a tmpfs) and
        their /run a tmpfs emptied at each start (as a machine's at boot: dockerd refuses to start while the pid
        file of the boot before names a running process, and in a container that is PID 1, itself)."""
        self.count = count
        self.disks = frozenset(disks)
        self.env = env or [{} for _ in range(count)]
        self.setup = setup
        self.tag = tag or uuid.uuid4().hex[:6]
        self.dir = Path(tempfile.mkdtemp(prefix="robocore-it-ssh-"))
        self.key = self.dir / "id_ed25519"
        self.known_hosts = self.dir / "known_hosts"
        self.ssh_config = self.dir / "ssh_config"
        self.network: Network | None = None
        self.hosts: list[RobotHost] = []
        self._clients: dict[int, Any] = {}
        self._saved_env: str | None = None
        self._env_set = False

    def __enter__(self) -> RobotFleet:
        try:
            self.start()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def start(self) -> None:
        """Build the image if needed, start the hosts, wait for sshd and dockerd, write the ssh config."""
        image = ensure_image()
        subprocess.run(["ssh-keygen", "-q", "-t", "ed25519", "-N", "", "-f", str(self.key)], check=True)
        public = self.key.with_suffix(".pub").read_text().strip()
        self.network = Network(docker_network_kw={"labels": {"dev.robocore.test": "1"}})
        self.network.create()
        for index in range(self.count):
            name = f"{PREFIX}-{self.tag}-{index}"
            container = (
                DockerContainer(image)
                .with_name(name)
                .with_env("AUTHORIZED_KEY", public)
                .with_network(self.network)
                .with_volume_mapping("/sys/fs/cgroup", "/sys/fs/cgroup", "rw")
            )
            kwargs: dict[str, Any] = {"cap_add": ["ALL"], "cap_drop": ["SYS_RESOURCE"], "hostname": name,
                                      "security_opt": ["seccomp=unconfined", "apparmor=unconfined"]}
            if index in self.disks:  # an anonymous volume: removed with the container (remove(v=True))
                kwargs["mounts"] = [Mount(target="/var/lib/docker", source=None, type="volume")]
                container.with_tmpfs_mount("/run", "exec")
            else:
                container.with_tmpfs_mount("/var/lib/docker", "exec")
            container.with_kwargs(**kwargs)
            for key, value in self.env[index].items():
                container.with_env(key, value)
            container.start()
            wrapped = container.get_wrapped_container()
            wrapped.reload()
            ip = wrapped.attrs["NetworkSettings"]["Networks"][self.network.name]["IPAddress"]
            self.hosts.append(RobotHost(name=name, container=container, ip=ip))
            if self.setup is not None:
                self.setup(self.hosts[-1])
        self.ssh_config.write_text(
            "Host *\n"
            f"  IdentityFile {self.key}\n"
            f"  UserKnownHostsFile {self.known_hosts}\n"
            "  StrictHostKeyChecking yes\n"
            "  IdentitiesOnly yes\n"
            "  BatchMode yes\n"
            "  LogLevel ERROR\n"
        )
        for host in self.hosts:
            self._wait_ready(host)
        self._saved_env = os.environ.get("ROBOCORE_SSH_CONFIG")
        os.environ["ROBOCORE_SSH_CONFIG"] = str(self.ssh_config)
        self._env_set = True

    def _wait_ready(self, host: RobotHost, timeout: float = 90) -> None:
        deadline = time.monotonic() + timeout
        last = [""]

        def answered(argv: list[str]) -> str | None:
            proc = subprocess.run(argv, capture_output=True, text=True)
            last[0] = proc.stderr
            return proc.stdout if proc.returncode == 0 and proc.stdout.strip() else None

        keys = wait_for(lambda: answered(["ssh-keyscan", "-T", "2", "-t", "ed25519", host.ip]), timeout)
        if keys is None:
            raise AssertionError(f"sshd on {host.name} ({host.ip}) did not come up: {last[0]}")
        with self.known_hosts.open("a") as handle:
            handle.write(keys)
        info = ["ssh", "-F", str(self.ssh_config), f"root@{host.ip}", "--", "docker", "info", "--format",
                "{{.ServerVersion}}"]
        if wait_for(lambda: answered(info), max(deadline - time.monotonic(), 0)) is None:
            raise AssertionError(f"dockerd on {host.name} ({host.ip}) did not come up: {last[0]}")

    def host_yaml(self, names: list[str]) -> str:
        """robot.yaml ``hosts:`` entries naming the fleet's hosts ``names[i]``."""
        rows = zip(names, self.hosts, strict=False)
        return "".join(f"  - name: {n}\n    ip: {h.ip}\n    user: root\n" for n, h in rows)

    def client(self, index: int) -> Any:
        """A docker-py client of host ``index``'s inner daemon, through robocore's own ssh adapter (one per
        host, closed with the fleet)."""
        from robocore.adapters.docker_hosts import client_for
        from robocore.config.model import Host

        if index not in self._clients:
            host = self.hosts[index]
            self._clients[index] = client_for(Host(name=host.name, ip=host.ip), timeout=600)
        return self._clients[index]

    def stop(self, index: int) -> None:
        """Stop host ``index`` (its address stops answering)."""
        self.hosts[index].container.get_wrapped_container().stop(timeout=2)

    def power_off(self, index: int, *, cut: bool) -> None:
        """Host ``index`` (one of ``disks``) goes down: with ``cut``, as in a power cut (every process of it killed
        at once, its daemon and containers with no word); else shut down (its daemon stops its own way, SIGTERM,
        as ``systemctl stop docker`` or a reboot does)."""
        assert index in self.disks, f"host {index} has no disk of its own: it would come back empty"
        wrapped = self.hosts[index].container.get_wrapped_container()
        if cut:
            wrapped.kill()
        else:
            wrapped.stop(timeout=30)
        wrapped.wait(timeout=60)

    def power_on(self, index: int, timeout: float = 90) -> None:
        """Start host ``index`` again after :meth:`power_off` and wait for its sshd and dockerd; it has the address
        it had (nothing else joined the network meanwhile), which is checked: a robot's or a manager's address is
        fixed in the fleet's files and in the swarm."""
        host = self.hosts[index]
        wrapped = host.container.get_wrapped_container()
        wrapped.start()
        wrapped.reload()
        assert self.network is not None
        ip = wrapped.attrs["NetworkSettings"]["Networks"][self.network.name]["IPAddress"]
        assert ip == host.ip, f"{host.name} came back at {ip}, not {host.ip}"
        self._wait_ready(host, timeout)

    def close(self) -> None:
        """Close the clients; remove the hosts, the network and the keys; restore ROBOCORE_SSH_CONFIG."""
        for client in self._clients.values():
            with contextlib.suppress(Exception):
                client.close()
        self._clients.clear()
        import docker

        with contextlib.closing(docker.from_env()) as client:  # by name: also a host that failed halfway
            for container in client.containers.list(all=True, filters={"name": f"{PREFIX}-{self.tag}-"}):
                if container.name.startswith(f"{PREFIX}-{self.tag}-"):
                    with contextlib.suppress(Exception):
                        container.remove(force=True, v=True)
        self.hosts.clear()
        if self.network is not None:
            with contextlib.suppress(Exception):
                self.network.remove()
            self.network = None
        if self._env_set:
            if self._saved_env is None:
                os.environ.pop("ROBOCORE_SSH_CONFIG", None)
            else:
                os.environ["ROBOCORE_SSH_CONFIG"] = self._saved_env
            self._env_set = False
        shutil.rmtree(self.dir, ignore_errors=True)
