"""The fleet registry's CA, as ``fleet join`` hands it to every robot host (fleet.yaml's ``registry_ca``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from robocore.errors import DockerError, HostError
from robocore.plan.registry_trust import CERTS_D, ca_file

if TYPE_CHECKING:
    import docker

    from robocore.commands.fleet_swarm import FleetProject
    from robocore.config.model import Host


@dataclass(frozen=True)
class Trust:
    """The CA certificate (``pem``, read from ``source``) of ``registry``, to be installed on robot hosts."""

    registry: str
    source: str
    pem: bytes

    @classmethod
    def of(cls, fleet: FleetProject) -> Trust | None:
        """The fleet's registry CA (read and checked now), None when fleet.yaml names none."""
        from robocore.config.registry_ca import read_registry_ca

        value = fleet.fleet.registry_ca
        registry = fleet.fleet.registry_for(fleet.project.robot)
        if value is None or registry is None:
            return None
        return cls(registry=registry, source=value, pem=read_registry_ca(value, fleet.project.root))

    @property
    def target(self) -> str:
        """Where a robot's daemon reads it."""
        return f"{CERTS_D}/{ca_file(self.registry)}"

    def dry_run(self) -> str:
        """What :meth:`install` would do, in one phrase."""
        return f"put {self.source} at {self.target} on it"

    def install(self, client: docker.DockerClient, host: Host) -> str:
        """Install the CA on the daemon of ``client`` (``host``'s): ``installed`` or ``unchanged``; a HostError
        naming the host and what to do when its daemon refuses."""
        from robocore.adapters.registry_trust import install_ca

        try:
            return install_ca(client, self.registry, self.pem)
        except DockerError as exc:
            raise HostError(f"{host.ip}: the registry's CA could not be installed: {exc.message}",
                            hint=f"copy {self.source} to {self.target} on {host.ip} yourself (as root), then run "
                                 "`fleet join` again") from None
