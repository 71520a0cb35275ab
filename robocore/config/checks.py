"""Cross-field and file-system checks of robot.yaml.

The checks run on :class:`Parts`: the hosts, components, common packages and discovery
servers that validated, each with its index in the file. A fully valid file gives every
part (:meth:`Parts.of`); a file with field errors still gives the parts that validated
(:func:`salvage`), so one run reports a bad type *and* an unknown ``runs_on`` host.

Each check yields ``(key path, message)``; the loader adds file and line.
"""

from __future__ import annotations

import os
import re
import stat
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

from pydantic import BaseModel, ValidationError

from robocore.config.desktop import gui_problems
from robocore.config.generations import generation_problems
from robocore.config.hints import Unknown, known_list
from robocore.config.hints import did_you_mean as did_you_mean
from robocore.config.mappings import device_problem, port_problem, read_only_project_path, volume_problem
from robocore.config.model import (
    CommonPackage,
    Component,
    DiscoveryServer,
    DockerAccess,
    Host,
    Robot,
)
from robocore.config.resources import over_limits
from robocore.config.sources import checkout_folder_problem, protocol_problem
from robocore.config.values import IMAGE_PATH, IMAGE_PREFIX, is_ipv6, shown
from robocore.files import is_inside, path_kind

KeyPath = tuple[str | int, ...]
Found = tuple[KeyPath, str]
M = TypeVar("M", bound=BaseModel)

#: Sections whose items carry a ``name`` that must be unique.
NAMED_SECTIONS = ("hosts", "components", "common_packages")


@dataclass(frozen=True)
class Parts:
    """The validated parts of one robot.yaml, each with its index in the file."""

    hosts: list[tuple[int, Host]] = field(default_factory=list)
    components: list[tuple[int, Component]] = field(default_factory=list)
    common_packages: list[tuple[int, CommonPackage]] = field(default_factory=list)
    #: Explicit ``discovery.servers`` entries; empty when the default server is used.
    servers: list[tuple[int, DiscoveryServer]] = field(default_factory=list)
    #: Every ``name`` written in each named section, validated or not, with its index; a section
    #: that is not a list at all is left out (its names are unknown, so references are not checked).
    names: dict[str, list[tuple[int, str]]] = field(default_factory=dict)
    #: ``image_prefix`` when it is valid (None when it is not: image names are then not checked).
    image_prefix: str | None = ""

    @classmethod
    def of(cls, robot: Robot) -> Parts:
        """All parts of a valid robot."""
        return cls(
            hosts=list(enumerate(robot.hosts)),
            components=list(enumerate(robot.components)),
            common_packages=list(enumerate(robot.common_packages)),
            servers=list(enumerate(robot.discovery.servers)),
            names={
                "hosts": [(i, h.name) for i, h in enumerate(robot.hosts)],
                "components": [(i, c.name) for i, c in enumerate(robot.components)],
                "common_packages": [(i, p.name) for i, p in enumerate(robot.common_packages)],
            },
            image_prefix=robot.image_prefix,
        )

    @property
    def host_names(self) -> list[str]:
        """Names of every host written in the file (even hosts with other problems)."""
        return [name for _, name in self.names.get("hosts", [])]


def salvage(data: Mapping[str, Any]) -> Parts:
    """The parts of raw robot.yaml data that validate on their own.

    An item with bad fields is validated again without them (so its other fields are still
    checked); an item that still fails, e.g. because a required key is bad, is left out.
    """
    discovery = data.get("discovery")
    servers = discovery.get("servers") if isinstance(discovery, dict) else None
    return Parts(
        hosts=salvage_list(data.get("hosts"), Host),
        components=salvage_list(data.get("components"), Component),
        common_packages=salvage_list(data.get("common_packages"), CommonPackage),
        servers=salvage_list(servers, DiscoveryServer),
        names={section: _raw_names(data[section]) for section in NAMED_SECTIONS if isinstance(data.get(section), list)},
        image_prefix=_valid_prefix(data.get("image_prefix", "")),
    )


def _valid_prefix(value: object) -> str | None:
    return value if isinstance(value, str) and re.fullmatch(IMAGE_PREFIX, value) else None


def _raw_names(items: list[Any]) -> list[tuple[int, str]]:
    return [
        (i, item["name"])
        for i, item in enumerate(items)
        if isinstance(item, dict) and isinstance(item.get("name"), str)
    ]


def salvage_list(items: object, model: type[M]) -> list[tuple[int, M]]:
    """The items of a raw list that validate as ``model`` (each with its index), an item with bad fields
    validated again without them; not a list: none."""
    if not isinstance(items, list):
        return []
    out: list[tuple[int, M]] = []
    for index, item in enumerate(items):
        valid = _salvage_item(item, model)
        if valid is not None:
            out.append((index, valid))
    return out


def _salvage_item(item: object, model: type[M]) -> M | None:
    if not isinstance(item, dict):
        return None
    try:
        return model.model_validate(item)
    except ValidationError as exc:
        bad = {error["loc"][0] for error in exc.errors() if error["loc"]}
    trimmed = {key: value for key, value in item.items() if key not in bad}
    try:
        return model.model_validate(trimmed)
    except ValidationError:
        return None


def check_robot(robot: Robot, project: Path | None) -> list[Found]:
    """Every cross-field problem of ``robot``; file-system checks only when ``project`` is given."""
    return [*generation_problems(robot), *check_parts(Parts.of(robot), project)]


def check_parts(parts: Parts, project: Path | None) -> list[Found]:
    """Every cross-field problem of ``parts``; file-system checks only when ``project`` is given."""
    found: list[Found] = [*_unique_names(parts), *_references(parts), *_discovery_reachable(parts),
                          *_remote_project_volumes(parts), *host_problems(parts.hosts), *_ipv6_discovery(parts),
                          *_components(parts), *_image_names(parts), *_git_sources(parts),
                          *gui_problems(parts.components)]
    if project is not None:
        root = project.resolve()
        found += _folders(parts, root)
        found += tls_file_problems(parts.hosts, root)
        found += _project_volumes(parts, root)
    return found


def _unique_names(parts: Parts) -> Iterator[Found]:
    for section in NAMED_SECTIONS:
        first: dict[str, int] = {}
        for index, name in parts.names.get(section, []):
            if name in first:
                yield (section, index, "name"), f"duplicate name {name!r} (also {section}[{first[name]}])"
            else:
                first[name] = index


def _references(parts: Parts) -> Iterator[Found]:
    if "hosts" not in parts.names:
        return
    hosts = Unknown("host", parts.host_names)
    for index, comp in parts.components:
        if comp.runs_on not in hosts:
            yield ("components", index, "runs_on"), hosts.message(comp.runs_on)
    seen: dict[tuple[str, int | None], int] = {}
    for index, server in parts.servers:
        if server.host not in hosts:
            yield ("discovery", "servers", index, "host"), hosts.message(server.host)
        endpoint = (server.host, server.port)
        if endpoint in seen:
            yield (("discovery", "servers", index),
                   f"two discovery servers on {server.host}:{server.port or 'the default port'} "
                   f"(also discovery.servers[{seen[endpoint]}])")
        else:
            seen[endpoint] = index


def _remote_project_volumes(parts: Parts) -> Iterator[Found]:
    """A read-only project volume of a remote component is synced with it: it must be inside the project."""
    hosts = {h.name: h for _, h in parts.hosts}
    for index, comp in parts.components:
        host = hosts.get(comp.runs_on)
        if host is None or host.is_local:
            continue
        for i, volume in enumerate(comp.volumes):
            relative = read_only_project_path(volume)
            if relative == ".":  # a path leaving the project (..) is refused with the volume itself
                yield (("components", index, "volumes", i),
                       f"{volume.split(':')[0]!r} is not a folder inside the project; sync copies read-only project "
                       f"paths to {host.name}, so use one inside the project folder (or an absolute path on "
                       f"{host.name})")


def _discovery_reachable(parts: Parts) -> Iterator[Found]:
    """A discovery server on a loopback address cannot be reached from the robot's other machines
    (those that run components or servers: a spare machine with nothing on it needs no discovery)."""
    used = {c.runs_on for _, c in parts.components} | {s.host for _, s in parts.servers}
    remote = [h.name for _, h in parts.hosts if not h.is_loopback and not h.is_local and h.name in used]
    if not remote:
        return
    by_name = {h.name: h for _, h in parts.hosts}
    others = known_list(remote)
    if parts.servers:
        for index, server in parts.servers:
            host = by_name.get(server.host)
            if host is not None and host.is_loopback:
                yield (("discovery", "servers", index, "host"),
                       f"discovery server on {host.name!r} listens on loopback address {host.ip!r}, which remote "
                       f"hosts ({others}) cannot reach; give {host.name} its LAN address or use another host")
    elif parts.hosts and parts.hosts[0][0] == 0 and parts.hosts[0][1].is_loopback:
        host = parts.hosts[0][1]
        yield (("hosts", 0, "ip"),
               f"the discovery server runs on the first host by default, but {host.ip!r} is a loopback address "
               f"that remote hosts ({others}) cannot reach; give {host.name} its LAN address, list a remote host "
               "first, or set discovery.servers")


def host_problems(hosts: Iterable[tuple[int, Host]]) -> Iterator[Found]:
    """How each host's Docker daemon is reached, checked (robot.yaml's hosts, fleet.yaml's manager and robots)."""
    for index, host in hosts:
        access = host.access
        if access is DockerAccess.tcp and not host.insecure:
            yield (("hosts", index, "docker"),
                   "plain TCP exposes the Docker daemon without authentication; use ssh or tls, "
                   "or set insecure: true on this host")
        if access is DockerAccess.tls and host.tls is None:
            yield ("hosts", index, "docker"), "docker: tls needs tls: {ca_cert, client_cert, client_key}"
        if access is not DockerAccess.tls and host.tls is not None:
            yield ("hosts", index, "tls"), f"tls files given but docker is {access.value!r}, not 'tls'"
        if host.insecure and access is not DockerAccess.tcp:
            yield ("hosts", index, "insecure"), "insecure: true only applies to docker: tcp"
        if host.docker_port is not None and access not in (DockerAccess.tcp, DockerAccess.tls):
            yield (("hosts", index, "docker_port"),
                   f"docker_port only applies to docker: tcp or tls (not {access.value!r})")
        if host.builds_here and host.is_local:
            yield (("hosts", index, "builds_here"),
                   "builds_here: true only applies to a remote host (this machine builds its own components anyway)")


def check_mapping(value: str, *, kind: str) -> str | None:
    """Why a ``devices`` (kind ``device``) or ``volumes`` entry is malformed, or None."""
    return device_problem(value) if kind == "device" else volume_problem(value)


def check_port(value: str) -> str | None:
    """Why a ``ports`` entry is malformed, or None."""
    return port_problem(value)


def _components(parts: Parts) -> Iterator[Found]:
    for index, comp in parts.components:
        base: KeyPath = ("components", index)
        if comp.image is not None:
            for key in ("folder", "apt_packages", "repositories"):
                if getattr(comp, key):
                    yield ((*base, key),
                           f"cannot be combined with image: (component {comp.name!r} uses a pre-built image)")
        for i, device in enumerate(comp.devices):
            problem = check_mapping(device, kind="device")
            if problem:
                yield (*base, "devices", i), problem
        for i, volume in enumerate(comp.volumes):
            problem = check_mapping(volume, kind="volume")
            if problem:
                yield (*base, "volumes", i), problem
        for i, port in enumerate(comp.ports):
            problem = check_port(port)
            if problem:
                yield (*base, "ports", i), problem
        if comp.ports and comp.network == "host":
            yield (*base, "ports"), "ports are ignored with network: host; remove them or use network: bridge"
        for problem in over_limits(comp.resources) if comp.resources is not None else ():
            yield (*base, "resources"), problem
    for index, pkg in parts.common_packages:
        if pkg.folder is None and pkg.repo is None:
            yield ("common_packages", index), "needs a folder or a repo"
        if pkg.branch is not None and pkg.repo is None:
            yield ("common_packages", index, "branch"), "branch needs repo"


def _inside(project: Path, rel: str) -> Path | None:
    target = (project / rel).resolve()
    try:
        target.relative_to(project)
    except ValueError:
        return None
    return target


def _folders(parts: Parts, project: Path) -> Iterator[Found]:
    entries: list[tuple[KeyPath, str | None, bool]] = [
        (("components", i, "folder"), c.folder, True) for i, c in parts.components
    ]
    entries += [(("common_packages", i, "folder"), p.folder, p.repo is None) for i, p in parts.common_packages]
    for path, rel, must_exist in entries:
        if rel is None:
            continue
        if not rel.strip():
            yield path, "folder is empty; name a folder inside the project"
            continue
        if Path(rel).is_absolute() or rel.startswith("~"):
            yield path, f"{rel!r} must be relative to the project folder"
            continue
        target = _inside(project, rel)
        if target is None:
            yield path, f"{rel!r} points outside the project folder"
        elif target == project:
            yield path, f"{rel!r} is the project folder itself; name a folder inside it"
        else:
            kind, reason = path_kind(target)
            if kind == "unusable":
                yield path, f"{shown(rel)} cannot be used as a folder: {reason}"
            elif must_exist and kind == "missing":
                yield path, f"folder {rel!r} does not exist (in {project})"
            elif kind == "file":
                yield path, f"{rel!r} is a file, not a folder"


def tls_file_problems(hosts: Iterable[tuple[int, Host]], project: Path) -> Iterator[Found]:
    """Each host's TLS files: regular files, a relative path inside ``project`` (the project folder, resolved)."""
    for index, host in hosts:
        if host.tls is None:
            continue
        for key in ("ca_cert", "client_cert", "client_key"):
            value: str = getattr(host.tls, key)
            path = Path(value).expanduser()
            if not path.is_absolute():
                path = project / path
            kind, reason = path_kind(path)
            if kind == "unusable":
                yield ("hosts", index, "tls", key), f"file {shown(value)} cannot be read: {reason}"
            elif kind != "file":
                yield ("hosts", index, "tls", key), f"file {shown(value)} not found"
            elif not stat.S_ISREG(os.stat(path).st_mode):
                yield ("hosts", index, "tls", key), f"file {shown(value)} is not a regular file (a FIFO or a device?)"
            elif not Path(value).expanduser().is_absolute() and not is_inside(path, project):
                why = ("leads through a symlink to a file outside" if Path(os.path.normpath(project / value))
                       .is_relative_to(os.path.normpath(project)) else "names a file outside")
                yield ("hosts", index, "tls", key), (f"file {shown(value)} {why} the project folder (a relative "
                                                     "path is read from it); name a file outside by its absolute path")


def discovery_hosts(parts: Parts) -> set[str]:
    """Names of the hosts that run a discovery server (the explicit ones, else the first host)."""
    if parts.servers:
        return {server.host for _, server in parts.servers}
    if parts.hosts and parts.hosts[0][0] == 0:
        return {parts.hosts[0][1].name}
    return set()


def _ipv6_discovery(parts: Parts) -> Iterator[Found]:
    """Fast DDS locators and ROS_DISCOVERY_SERVER are written as IPv4 ``address:port``: a host in use with
    an IPv6 address cannot take part in discovery."""
    servers = discovery_hosts(parts)
    running = {c.runs_on for _, c in parts.components}
    for index, host in parts.hosts:
        if not is_ipv6(host.ip) or host.name not in servers | running:
            continue
        role = "runs a discovery server" if host.name in servers else "runs components"
        yield (("hosts", index, "ip"),
               f"{host.ip!r} is an IPv6 address, and DDS discovery over IPv6 is not supported yet ({host.name} "
               f"{role}); use its IPv4 address or a host name")


def _git_sources(parts: Parts) -> Iterator[Found]:
    """Protocols that need an opt-in, and checkout folders (given or derived from the URL) that are unsafe or shared."""
    for index, pkg in parts.common_packages:
        if pkg.repo is not None:
            problem = protocol_problem(pkg.repo, pkg.allow_protocol)
            if problem:
                yield ("common_packages", index, "repo"), problem
    for index, comp in parts.components:
        folders: dict[str, int] = {}
        for i, repo in enumerate(comp.repositories):
            base: KeyPath = ("components", index, "repositories", i)
            problem = protocol_problem(repo.url, repo.allow_protocol)
            if problem:
                yield (*base, "url"), problem
            folder = repo.checkout_folder
            if repo.folder is None and checkout_folder_problem(folder) is not None:
                yield ((*base, "url"),
                       f"the checkout folder taken from this URL, {shown(folder)}, is not a safe folder name; "
                       "set folder: to a relative folder under src/")
                continue
            if folder in folders:
                key = "folder" if repo.folder is not None else "url"
                yield ((*base, key),
                       f"two repositories use folder {folder!r} (also repositories[{folders[folder]}])")
            else:
                folders[folder] = i


def _project_volumes(parts: Parts, project: Path) -> Iterator[Found]:
    """A read-only project volume is copied to the component's host by sync: one that leads outside the
    project through a symlink (to ~/.ssh, say) needs ``allow_outside_project: true`` on its component."""
    for index, comp in parts.components:
        if comp.allow_outside_project:
            continue
        for i, volume in enumerate(comp.volumes):
            target = outside_target(project, volume)
            if target is not None:
                source = volume.split(":")[0]
                yield (("components", index, "volumes", i),
                       f"{shown(source)} leads outside the project (to {shown(str(target))}), and sync would copy "
                       f"that to {comp.runs_on}; point it inside the project, or set allow_outside_project: true "
                       "on this component")


def outside_target(project: Path, volume: str) -> Path | None:
    """Where a read-only project volume that stays inside the project by name resolves, when that is outside
    ``project`` (a resolved project folder); None for any other volume."""
    relative = read_only_project_path(volume)
    if relative is None or relative == "." or relative.split("/")[0] == "..":
        return None
    target = (project / relative).resolve()
    return None if target == project or target.is_relative_to(project) else target


#: Stands for the default image prefix (the project folder's name and '-') when robot.yaml sets none.
_DEFAULT_PREFIX = "robot-"


def _image_names(parts: Parts) -> Iterator[Found]:
    """A component that robocore builds an image for names that image (``<image_prefix><name>``): Docker
    takes lower-case names only, with one separator between letters and digits."""
    if parts.image_prefix is None:
        return
    prefix = parts.image_prefix or _DEFAULT_PREFIX
    for index, comp in parts.components:
        if comp.image is None and not re.fullmatch(IMAGE_PATH, prefix + comp.name):
            yield (("components", index, "name"),
                   f"{comp.name!r} would name the image {prefix + comp.name!r}, which Docker refuses: use lower case, "
                   "with one '.', '_', '__' or '-' between letters and digits")
