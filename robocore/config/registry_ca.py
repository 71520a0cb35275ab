"""fleet.yaml's ``registry_ca``: the CA certificate that signed the fleet registry's TLS certificate.

A team's own registry often has a certificate of the team's own CA, which no robot's Docker daemon trusts out of
the box. ``registry_ca: certs/registry-ca.crt`` names that CA's certificate (PEM), a file of the project, which
``fleet join`` installs on every robot host where its daemon reads it (``/etc/docker/certs.d/<registry>/ca.crt``).

The file is checked as robot.yaml's TLS files are (a regular file, a relative path inside the project, an absolute
path for a file outside it) and, as it is sent to every robot, read here once: at most :data:`MAX_CA_BYTES`,
PEM text holding at least one ``CERTIFICATE`` block and no private key. A registry must be set (fleet.yaml's or
robot.yaml's): a CA trusts nothing without one.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Iterator
from pathlib import Path

from robocore.config.values import shown
from robocore.errors import UsageError
from robocore.files import is_inside, path_kind

#: Largest CA file read (a CA bundle of a few certificates is a few kB).
MAX_CA_BYTES = 65_536
#: What a PEM certificate block starts with.
PEM_CERTIFICATE = b"-----BEGIN CERTIFICATE-----"
#: What a key's PEM block says (never sent to a robot: a CA file holding a key is refused).
PEM_KEY = b"PRIVATE KEY-----"

Found = tuple[tuple[str | int, ...], str]


def ca_path(value: str, project: Path) -> Path:
    """The file ``value`` names: relative to the project folder, or absolute (``~`` expanded)."""
    path = Path(value).expanduser()
    return path if path.is_absolute() else project / path


def registry_ca_problems(value: str | None, project: Path | None, *, has_registry: bool) -> Iterator[Found]:
    """Problems of fleet.yaml's ``registry_ca`` (``value``; None: not set); ``project`` (the project folder, resolved)
    adds the checks that read the file."""
    if value is None:
        return
    key: tuple[str | int, ...] = ("registry_ca",)
    if not has_registry:
        yield key, "registry_ca is the CA of the fleet's registry, but no registry is set (here or in robot.yaml)"
    if project is None:
        return
    path = ca_path(value, project)
    kind, reason = path_kind(path)
    if kind == "unusable":
        yield key, f"file {shown(value)} cannot be read: {reason}"
        return
    if kind != "file":
        yield key, f"file {shown(value)} not found"
        return
    if not stat.S_ISREG(os.stat(path).st_mode):
        yield key, f"file {shown(value)} is not a regular file (a FIFO or a device?)"
        return
    if not Path(value).expanduser().is_absolute() and not is_inside(path, project):
        why = ("leads through a symlink to a file outside" if Path(os.path.normpath(project / value))
               .is_relative_to(os.path.normpath(project)) else "names a file outside")
        yield key, (f"file {shown(value)} {why} the project folder (a relative path is read from it); name a file "
                    "outside by its absolute path")
        return
    why = pem_problem(_head(path))
    if why:
        yield key, f"file {shown(value)} {why}"


def pem_problem(data: bytes) -> str:
    """Why ``data`` is no CA certificate to send to robots ("" when it is one)."""
    if len(data) > MAX_CA_BYTES:
        return f"is larger than {MAX_CA_BYTES:,} bytes: not a CA certificate"
    if PEM_KEY in data:
        return "holds a private key: give the CA's certificate only (a key is never sent to the robots)"
    if PEM_CERTIFICATE not in data:
        return "is not a PEM certificate (no '-----BEGIN CERTIFICATE-----' line)"
    return ""


def _head(path: Path) -> bytes:
    with path.open("rb") as handle:
        return handle.read(MAX_CA_BYTES + 1)


def read_registry_ca(value: str, project: Path) -> bytes:
    """The CA certificate ``value`` names (checked as :func:`registry_ca_problems` does; a UsageError naming it
    otherwise: the file may have changed since fleet.yaml was checked)."""
    found = list(registry_ca_problems(value, project.resolve(), has_registry=True))
    if found:
        raise UsageError(f"fleet.yaml: registry_ca: {found[0][1]}")
    data = _head(ca_path(value, project.resolve()))
    why = pem_problem(data)
    if why:
        raise UsageError(f"fleet.yaml: registry_ca: file {shown(value)} {why}")
    return data
