"""Host addresses as robocore compares and accepts them: one machine each.

robot.yaml's and fleet.yaml's hosts are reached by ssh, rsync and Docker at their ``ip``, and fleet.yaml compares
the addresses of its robots' hosts. An address that names no one machine is refused (the unspecified address, an
IPv4-mapped loopback address, which a loopback rule written for ``127.0.0.1`` would not see), and an IPv4-mapped
IPv6 address is compared as the IPv4 address it is.
"""

from __future__ import annotations

import ipaddress


def refuse_no_machine(value: str) -> None:
    """Refuse the addresses that name no one machine: the unspecified address (``0.0.0.0``, ``::``: "any", which a
    client reaches as this machine) and an IPv4-mapped IPv6 address of loopback or "any" (``::ffff:127.0.0.1``,
    which would pass a loopback rule written for ``127.0.0.1``)."""
    try:
        address = ipaddress.ip_address(value)
    except ValueError:
        return
    mapped = address.ipv4_mapped if isinstance(address, ipaddress.IPv6Address) else None
    if address.is_unspecified or (mapped is not None and mapped.is_unspecified):
        raise ValueError(f"{value} is the unspecified address ('any'), not a machine's address; give the host's "
                         "address")
    if mapped is not None and mapped.is_loopback:
        raise ValueError(f"{value} is the loopback address {mapped} written as IPv6; write {mapped} (or the "
                         "host's network address)")


def address_key(address: str) -> str:
    """``address`` as compared with another: an IP address in its canonical form, an IPv4-mapped IPv6 address as its
    IPv4 address (``::ffff:192.0.2.5`` is ``192.0.2.5``), a host name in lower case without a trailing dot."""
    try:
        found = ipaddress.ip_address(address.strip("[]"))
    except ValueError:
        return address.lower().rstrip(".")
    mapped = found.ipv4_mapped if isinstance(found, ipaddress.IPv6Address) else None
    return str(mapped or found)


def names_no_machine(value: str) -> bool:
    """True for an address :func:`refuse_no_machine` refuses (a rule of meaning the schema's pattern leaves out)."""
    try:
        refuse_no_machine(value)
    except ValueError:
        return True
    return False
