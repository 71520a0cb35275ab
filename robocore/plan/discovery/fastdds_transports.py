"""Fast DDS transports as robocore sets them: the XML blocks and environment of shared memory with UDP, or UDP only.

Kept apart from :mod:`robocore.plan.discovery.fastdds` (servers, profiles, readiness), which renders these
blocks into every client and super client profile.
"""

from __future__ import annotations

from dataclasses import dataclass

from robocore.plan.discovery.base import Transport


@dataclass(frozen=True)
class TransportSettings:
    """How Fast DDS is told the transport: an environment variable and the XML blocks of its transports."""

    environment: dict[str, str]
    descriptors: str  # <transport_descriptors> block of a profile
    rtps: str  # participant <rtps> lines that use those descriptors only


#: Fast DDS's shared-memory port health check, in ms (its default: 1000). A process that opens another's port, as
#: a new node does for each peer it matches on its host, first checks that the port's listening thread is alive;
#: when that thread has not woken since Fast DDS's watchdog last looked (about one open in six with the default),
#: the opener sleeps a third of this value, its discovery held meanwhile: with the default a new node can go
#: silent for a third of a second after taking in its first new peer. A shorter check shortens that sleep; it
#: stays long enough that a port is taken for dead (and made anew) only when its listening thread, which wakes
#: every third of this value, misses about two wake-ups in a row. The measurements: docs/design-notes.md,
#: "Shared-memory port health check: 300 ms".
SHM_HEALTHY_CHECK_MS = 300


def _descriptor(transport_id: str, kind: str, settings: str = "") -> str:
    return (
        "      <transport_descriptor>\n"
        f"        <transport_id>{transport_id}</transport_id>\n"
        f"        <type>{kind}</type>\n"
        f"{settings}"
        "      </transport_descriptor>\n"
    )


def transport_settings(transport: Transport) -> TransportSettings:
    """The environment and XML that give Fast DDS ``transport``: shared memory (with a quicker port health check,
    :data:`SHM_HEALTHY_CHECK_MS`) and UDPv4, as Fast DDS's defaults, else UDPv4 only.

    Humble's Fast DDS 2.6 has no ``FASTDDS_BUILTIN_TRANSPORTS``, so the profiles say it too.
    """
    used = {"robocore_udp": _descriptor("robocore_udp", "UDPv4")}
    environment = {"FASTDDS_BUILTIN_TRANSPORTS": "UDPv4"}
    if transport.shared_memory:
        check = f"        <healthy_check_timeout_ms>{SHM_HEALTHY_CHECK_MS}</healthy_check_timeout_ms>\n"
        used = {"robocore_shm": _descriptor("robocore_shm", "SHM", check), **used}
        environment = {}
    descriptors = f"    <transport_descriptors>\n{''.join(used.values())}    </transport_descriptors>\n"
    rtps = (
        f"        <userTransports>{''.join(f'<transport_id>{name}</transport_id>' for name in used)}</userTransports>\n"
        "        <useBuiltinTransports>false</useBuiltinTransports>\n"
    )
    return TransportSettings(environment, descriptors, rtps)
