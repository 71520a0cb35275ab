"""The release plan: which image of which arch is pushed under which name, and the multi-arch names (pure).

``release --tag V`` pushes each arch's image of a repository as ``<registry>/<repo>:V-<arch>`` and then one
manifest list ``<registry>/<repo>:V`` naming them, so that every host pulls ``<registry>/<repo>:V`` and gets
its own arch. The list is made with the Docker CLI's ``docker manifest create`` and ``push`` (docker-py has
no manifest-list API), which read each arch's manifest back from the registry and take its platform from
the image's config: the list can only name what the registry holds.
"""

from __future__ import annotations

import ipaddress
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from robocore.errors import UsageError
from robocore.plan import naming


@dataclass(frozen=True)
class LocalImage:
    """An image of this machine that a release carries: its repository (no registry), arch and local reference."""

    repo: str
    arch: str
    source: str  # repository:tag on this machine


@dataclass(frozen=True)
class Push:
    """One arch's image pushed under its own tag."""

    source: str  # repository:tag on this machine
    target: str  # <registry>/<repo>
    tag: str  # V-<arch>
    arch: str

    @property
    def ref(self) -> str:
        """``target:tag``."""
        return f"{self.target}:{self.tag}"


@dataclass(frozen=True)
class ManifestList:
    """The multi-arch name of one repository and the per-arch references it names."""

    ref: str  # <registry>/<repo>:V
    members: tuple[str, ...]  # <registry>/<repo>:V-<arch>, one per arch


@dataclass(frozen=True)
class ReleasePlan:
    """Everything a release pushes, in order: the per-arch images, then the lists."""

    version: str
    pushes: tuple[Push, ...]
    lists: tuple[ManifestList, ...]


def arch_tag(version: str, arch: str) -> str:
    """The tag of one arch's image of a release: ``V-<arch>`` (a UsageError when it is not a valid tag)."""
    tag = f"{version}-{arch}"
    if not naming.is_image_tag(tag):
        raise UsageError(f"{version!r} is too long for a release tag: {tag!r} is not a valid image tag",
                         hint="a version of at most 120 letters, digits, '_', '.', '-'")
    return tag


def plan_release(registry: str, version: str, images: Sequence[LocalImage]) -> ReleasePlan:
    """The pushes and manifest lists of a release of ``images`` under ``version`` to ``registry``."""
    prefix = registry.rstrip("/")
    pushes = tuple(Push(source=i.source, target=f"{prefix}/{i.repo}", tag=arch_tag(version, i.arch), arch=i.arch)
                   for i in images)
    by_target: dict[str, list[str]] = {}
    for push in pushes:
        by_target.setdefault(push.target, []).append(push.ref)
    lists = tuple(ManifestList(ref=f"{target}:{version}", members=tuple(sorted(set(refs))))
                  for target, refs in by_target.items())
    return ReleasePlan(version=version, pushes=pushes, lists=lists)


def manifest_create_argv(docker: str, manifest: ManifestList, *, insecure: bool) -> list[str]:
    """``docker manifest create``: the list ``manifest.ref`` naming its members (``--amend``: a list of that
    name left by an earlier release on this machine is replaced, not an error)."""
    return [docker, "manifest", "create", "--amend", *(["--insecure"] if insecure else []), "--",
            manifest.ref, *manifest.members]


def manifest_push_argv(docker: str, manifest: ManifestList, *, insecure: bool) -> list[str]:
    """``docker manifest push``: the list to the registry (``--purge``: nothing is left on this machine)."""
    return [docker, "manifest", "push", "--purge", *(["--insecure"] if insecure else []), "--", manifest.ref]


def registry_host(registry: str) -> str:
    """The ``host[:port]`` part of a registry setting (``HOST[:PORT][/PATH]``)."""
    return registry.split("/", 1)[0]


def plain_http(registry: str, registry_config: Mapping[str, Any]) -> bool:
    """Whether this machine's Docker daemon talks to ``registry`` over plain HTTP, as the CLI must then too
    (``--insecure``): a loopback registry, or one the daemon lists as insecure (``RegistryConfig`` of
    ``docker info``: ``IndexConfigs[host].Secure`` false, or an address in ``InsecureRegistryCIDRs``)."""
    host = registry_host(registry)
    name = host.rsplit(":", 1)[0] if not host.endswith("]") else host
    name = name.strip("[]")
    index = (registry_config.get("IndexConfigs") or {}).get(host)
    if isinstance(index, Mapping) and index.get("Secure") is False:
        return True
    if name == "localhost":
        return True
    try:
        address = ipaddress.ip_address(name)
    except ValueError:
        return False
    if address.is_loopback:
        return True
    for cidr in registry_config.get("InsecureRegistryCIDRs") or []:
        try:
            if address in ipaddress.ip_network(str(cidr), strict=False):
                return True
        except ValueError:
            continue
    return False


def is_released(registry: str | None, ref: str) -> bool:
    """True when ``ref`` names an image of a release (under the robot's registry), which a host pulls itself."""
    return registry is not None and registry != "" and ref.startswith(registry.rstrip("/") + "/")
