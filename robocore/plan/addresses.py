"""Host addresses in the form each tool reads them (pure).

An IPv6 address is written bare where a tool takes a host on its own (ssh's destination, a socket
address) and in brackets where a port or a path follows a colon (URLs, rsync's and scp's
``host:path``): rsync would read ``fe80::1:/srv`` as its daemon syntax (``host::module``).
"""

from __future__ import annotations

import ipaddress


def bare(address: str) -> str:
    """``address`` without the brackets of a bracketed IPv6 address (``[fe80::1]`` -> ``fe80::1``)."""
    if address.startswith("[") and address.endswith("]"):
        return address[1:-1]
    return address


def is_ipv6(address: str) -> bool:
    """True for an IPv6 address, bracketed or not (a zone such as ``%eth0`` included)."""
    try:
        return isinstance(ipaddress.ip_address(bare(address)), ipaddress.IPv6Address)
    except ValueError:
        return False


def bracketed(address: str) -> str:
    """An IPv6 address in brackets, for ``host:port`` and ``host:path`` forms; other addresses as they are."""
    return f"[{bare(address)}]" if is_ipv6(address) else address


def url_host(address: str, port: int) -> str:
    """``host:port`` for a URL (``[fe80::1]:2376``)."""
    return f"{bracketed(address)}:{port}"
