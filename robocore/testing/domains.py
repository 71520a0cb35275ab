"""The ROS domain of each test run: one that no other run on this machine holds and no robot running here uses.

Robots of one domain on one host share its DDS ports, and on host networking and IPC its shared-memory ports too:
a test run in a domain another robot uses could hear that robot, or restart unheard by its own nodes for seconds.
A run holds its domain with a listening loopback port (:data:`DOMAIN_LOCK_PORT` + the domain), which the kernel
lets go of when the process ends, however it ends; whatever else deploys robots here for tests (robocore's own
integration suites) holds its domains the same way (:func:`hold_domain`).
"""

from __future__ import annotations

import random
import socket
from typing import Any

from robocore.plan import naming
from robocore.testing.errors import BringUpError

#: ROS domains handed out to runs (safe on Linux), and the loopback TCP ports that reserve them.
DOMAINS = range(1, 102)
DOMAIN_LOCK_PORT = 22000


def hold_domain(domain: int) -> socket.socket | None:
    """The socket that holds ROS domain ``domain`` for this process until it is closed (a listening loopback port,
    :data:`DOMAIN_LOCK_PORT` + ``domain``: the kernel lets it go when the process ends, however it ends), or None
    when another run on this machine holds it. Whatever else deploys robots on this machine for tests can hold
    their domains the same way, so that no run is handed one of them."""
    holder = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        holder.bind(("127.0.0.1", DOMAIN_LOCK_PORT + domain))
        holder.listen(1)
    except OSError:
        holder.close()
        return None
    return holder


def domains_in_use(client: Any) -> set[int]:
    """The ROS domains of the robocore containers running on this machine's daemon (``ROS_DOMAIN_ID`` of each):
    a robot deployed here, a developer's or another suite's, that holds no reservation. Two robots of one domain on
    one host share its DDS ports, and on host networking and IPC its shared-memory ports too: one restarting can go
    unheard by the other for seconds."""
    from docker.errors import DockerException

    try:
        running = client.containers.list(filters={"label": naming.LABEL_ROLE}, ignore_removed=True)
    except DockerException:
        return set()
    return {domain for domain in map(domain_of, running) if domain is not None}


def domain_of(container: Any) -> int | None:
    """The ROS domain a docker-py ``container`` runs in (its ``ROS_DOMAIN_ID``), None when it sets none."""
    for item in (container.attrs.get("Config") or {}).get("Env") or []:
        name, _, value = str(item).partition("=")
        if name == "ROS_DOMAIN_ID" and value.isdigit():
            return int(value)
    return None


def reserve_domain(client: Any = None) -> tuple[int, socket.socket]:
    """A ROS domain no other run on this machine holds and, given the local daemon's ``client``, no robocore
    container running on it uses (:func:`domains_in_use`), and the socket that holds it until closed."""
    taken = domains_in_use(client) if client is not None else set()
    candidates = [domain for domain in DOMAINS if domain not in taken]
    random.shuffle(candidates)
    for domain in candidates:
        holder = hold_domain(domain)
        if holder is not None:
            return domain, holder
    raise BringUpError(f"every ROS domain {DOMAINS.start}-{DOMAINS.stop - 1} is held by another test run or used by "
                       "a robot running here")
