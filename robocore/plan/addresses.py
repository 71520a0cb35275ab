"""Host addresses in the form each tool reads them (pure).

An IPv6 address is written bare where a tool takes a host on its own (ssh's destination, a socket
address) and in brackets where a port or a path follows a colon (URLs, rsync's and scp's
``host:path``): rsync would read ``fe80::1:/srv`` as its daemon syntax (``host::module``).
"""

from __future__ import annotations

from robocore.config.model import is_loopback_address
from robocore.config.values import is_ipv6


def bare(address: str) -> str:
    """``address`` without the brackets of a bracketed IPv6 address (``[fe80::1]`` -> ``fe80::1``)."""
    if address.startswith("[") and address.endswith("]"):
        return address[1:-1]
    return address


def bracketed(address: str) -> str:
    """An IPv6 address in brackets, for ``host:port`` and ``host:path`` forms; other addresses as they are."""
    return f"[{bare(address)}]" if is_ipv6(bare(address)) else address


def url_host(address: str, port: int) -> str:
    """``host:port`` for a URL (``[fe80::1]:2376``)."""
    return f"{bracketed(address)}:{port}"


#: The name by which a container on a bridge network reaches its own host: Docker maps it to the
#: bridge's gateway when the container is created with ``extra_hosts: {name: host-gateway}``.
HOST_GATEWAY_NAME = "host.docker.internal"
HOST_GATEWAY = "host-gateway"


def reachable_from_container(address: str, network_mode: str) -> str:
    """``address`` (of a service on the container's host or elsewhere) as a container on ``network_mode`` reaches it.

    With host networking a container shares its host's addresses, loopback included. On a bridge
    network, loopback is the container's own: a loopback address becomes :data:`HOST_GATEWAY_NAME`,
    the host as seen from the bridge (services listening on every interface answer there).
    """
    if network_mode == "bridge" and is_loopback_address(address):
        return HOST_GATEWAY_NAME
    return address


def extra_hosts(network_mode: str) -> tuple[tuple[str, str], ...]:
    """The ``extra_hosts`` entries a container on ``network_mode`` needs for :func:`reachable_from_container`."""
    return ((HOST_GATEWAY_NAME, HOST_GATEWAY),) if network_mode == "bridge" else ()

