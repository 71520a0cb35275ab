"""A fleet registry's TLS trust and login, as plain data: where a robot's daemon reads the registry's CA, the
archive that puts it there, and what a failed push or pull tells the user to do.

Docker reads a registry's own CA from ``/etc/docker/certs.d/<host[:port]>/ca.crt`` at each pull (no daemon
restart); the folder is named by the registry's host and port, without a path. The messages here name the
registry and the one thing to do; none ever holds a credential (only what Docker or the registry said).
"""

from __future__ import annotations

import io
import tarfile

#: Where a Docker daemon reads registries' CAs (Debian's docker.io, Docker CE; not rootless Docker).
CERTS_D = "/etc/docker/certs.d"


def registry_host(registry: str) -> str:
    """The ``host[:port]`` of ``registry`` (``reg.lan:5000/team`` -> ``reg.lan:5000``): the certs.d folder's name
    and the key of a ``docker login``."""
    return registry.split("/", 1)[0]


def ca_file(registry: str) -> str:
    """Path of ``registry``'s CA under :data:`CERTS_D`, relative to it: ``<host[:port]>/ca.crt``."""
    return f"{registry_host(registry)}/ca.crt"


def ca_archive(registry: str, pem: bytes, mtime: int = 0) -> bytes:
    """A tar archive holding ``<host[:port]>/ca.crt`` (``pem``, mode 0644: a CA certificate is public) and its
    folder (0755), both dated ``mtime``, to be unpacked in :data:`CERTS_D`."""
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w", format=tarfile.PAX_FORMAT) as tar:
        folder = tarfile.TarInfo(registry_host(registry))
        folder.type, folder.mode, folder.mtime = tarfile.DIRTYPE, 0o755, mtime
        tar.addfile(folder)
        entry = tarfile.TarInfo(ca_file(registry))
        entry.size, entry.mode, entry.mtime = len(pem), 0o644, mtime
        tar.addfile(entry, io.BytesIO(pem))
    return buffer.getvalue()


def file_in_archive(data: bytes) -> bytes | None:
    """The one regular file of a tar archive (what Docker's archive API returns for a file), None when there is
    none (a missing file, a folder)."""
    with tarfile.open(fileobj=io.BytesIO(data), mode="r") as tar:
        for member in tar.getmembers():
            if member.isfile():
                extracted = tar.extractfile(member)
                return extracted.read() if extracted is not None else None
    return None


def trust_problem(detail: str) -> str:
    """What kind of registry problem Docker's or the registry's ``detail`` is: ``login`` (no or wrong
    credentials), ``ca`` (a certificate this side does not trust), ``""`` (something else)."""
    text = detail.lower()
    if "x509" in text or "certificate" in text or "tls: " in text:
        return "ca"
    if any(word in text for word in ("unauthorized", "authentication required", "no basic auth credentials",
                                     "denied", "401")):
        return "login"
    return ""


def push_hint(registry: str, detail: str) -> str:
    """The one thing to do when this machine's push to ``registry`` failed with ``detail``."""
    host = registry_host(registry)
    kind = trust_problem(detail)
    if kind == "login":
        return f"log this machine's Docker in to the registry: docker login {host}"
    if kind == "ca":
        return (f"this machine's Docker does not trust {host}'s certificate: copy its CA to "
                f"{CERTS_D}/{ca_file(registry)} here (fleet.yaml's registry_ca is what robots get)")
    return f"is the registry {host} reachable (and trusted) from this machine?"


def pull_hint(image: str, error: str) -> str:
    """What a robot's task that could not start because its ``image`` (a registry's, ``host[:port]/repo...``) is
    missing (``error``: ``No such image: ...``, all Swarm reports of a failed pull) should tell the user; "" for any
    other error or image."""
    host = image.split("/", 1)[0] if "/" in image else ""
    if "no such image" not in error.lower() or not ("." in host or ":" in host or host == "localhost"):
        return ""
    return (f"the robot could not pull it from {host}: is the registry up and reachable from the robot, is this "
            f"machine logged in to it (docker login {host}: the "
            "manager hands that login to the robots) and is the registry's CA on the robot (fleet.yaml's "
            "registry_ca, installed by fleet join)? The robot's dockerd log has the registry's answer")
