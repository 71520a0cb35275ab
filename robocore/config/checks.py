"""Cross-field and file-system checks of a validated robot.yaml.

Each check yields ``(key path, message)``; the loader adds file and line.
"""

from __future__ import annotations

import ipaddress
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

from robocore.config.model import DockerAccess, Robot, port_pattern

KeyPath = tuple[str | int, ...]
Found = tuple[KeyPath, str]


def check_robot(robot: Robot, project: Path | None) -> list[Found]:
    """Every cross-field problem of ``robot``; file-system checks only when ``project`` is given."""
    found: list[Found] = []
    found += _unique_names(robot)
    found += _references(robot)
    found += _hosts(robot)
    found += _components(robot)
    if project is not None:
        found += _folders(robot, project.resolve())
    return found


def _unique_names(robot: Robot) -> Iterator[Found]:
    for section, items in (("hosts", robot.hosts), ("components", robot.components), ("common_packages", robot.common_packages)):
        counts = Counter(item.name for item in items)
        for index, item in enumerate(items):
            if counts[item.name] > 1 and [i.name for i in items].index(item.name) != index:
                yield (section, index, "name"), f"duplicate name {item.name!r}"


def _known(names: list[str]) -> str:
    return ", ".join(names) if names else "none"


def _references(robot: Robot) -> Iterator[Found]:
    hosts = [h.name for h in robot.hosts]
    for index, comp in enumerate(robot.components):
        if comp.runs_on not in hosts:
            yield ("components", index, "runs_on"), f"unknown host {comp.runs_on!r} (known: {_known(hosts)})"
    for index, server in enumerate(robot.discovery.servers):
        if server.host not in hosts:
            yield ("discovery", "servers", index, "host"), f"unknown host {server.host!r} (known: {_known(hosts)})"
    endpoints = Counter((s.host, s.port) for s in robot.discovery.servers)
    for index, server in enumerate(robot.discovery.servers):
        if endpoints[(server.host, server.port)] > 1 and robot.discovery.servers.index(server) != index:
            yield ("discovery", "servers", index), f"two discovery servers on {server.host}:{server.port}"


def _hosts(robot: Robot) -> Iterator[Found]:
    for index, host in enumerate(robot.hosts):
        access = host.access
        if access is DockerAccess.tcp and not host.insecure:
            yield (("hosts", index, "docker"),
                   "plain TCP exposes the Docker daemon without authentication; use ssh or tls, "
                   "or set insecure: true on this host")
        if access is DockerAccess.tls and host.tls is None:
            yield ("hosts", index, "tls"), "docker: tls needs tls: {ca_cert, client_cert, client_key}"
        if access is not DockerAccess.tls and host.tls is not None:
            yield ("hosts", index, "tls"), "tls files given but docker is not 'tls'"
        if host.insecure and access is not DockerAccess.tcp:
            yield ("hosts", index, "insecure"), "insecure: true only applies to docker: tcp"
        if access is DockerAccess.local:
            try:
                loopback = ipaddress.ip_address(host.ip).is_loopback
            except ValueError:
                loopback = host.ip == "localhost"
            if not loopback and host.docker is DockerAccess.local:
                # explicitly local but with a remote-looking address: allowed (the dev machine's LAN ip)
                pass


def _check_mapping(value: str, *, kind: str) -> str | None:
    parts = value.split(":")
    if kind == "device":
        if not 1 <= len(parts) <= 3 or not parts[0].startswith("/"):
            return f"{value!r} is not host_path[:container_path[:rwm]]"
        if len(parts) >= 2 and not parts[1].startswith("/"):
            return f"{value!r}: container path must be absolute"
        if len(parts) == 3 and (not parts[2] or set(parts[2]) - set("rwm")):
            return f"{value!r}: permissions must be letters of 'rwm'"
        return None
    # volume
    if not 2 <= len(parts) <= 3 or not parts[0] or not parts[1].startswith("/"):
        return f"{value!r} is not host_path:container_path[:ro|rw]"
    if len(parts) == 3 and parts[2] not in {"ro", "rw"}:
        return f"{value!r}: mode must be ro or rw"
    return None


def _check_port(value: str) -> str | None:
    match = port_pattern().match(value)
    if not match:
        return f"{value!r} is not [ip:]host_port:container_port[/tcp|udp]"
    numbers = [match.group(g) for g in ("host", "host_end", "cont", "cont_end") if match.group(g)]
    if any(not 1 <= int(n) <= 65535 for n in numbers):
        return f"{value!r}: ports must be between 1 and 65535"
    return None


def _components(robot: Robot) -> Iterator[Found]:
    for index, comp in enumerate(robot.components):
        base: KeyPath = ("components", index)
        if comp.image is not None:
            for key in ("folder", "apt_packages", "repositories"):
                if getattr(comp, key):
                    yield (*base, key), f"cannot be combined with image: (component {comp.name!r} uses a pre-built image)"
        for i, device in enumerate(comp.devices):
            problem = _check_mapping(device, kind="device")
            if problem:
                yield (*base, "devices", i), problem
        for i, volume in enumerate(comp.volumes):
            problem = _check_mapping(volume, kind="volume")
            if problem:
                yield (*base, "volumes", i), problem
        for i, port in enumerate(comp.ports):
            problem = _check_port(port)
            if problem:
                yield (*base, "ports", i), problem
        for key in comp.environment:
            if not key or not (key[0].isalpha() or key[0] == "_") or not all(ch.isalnum() or ch == "_" for ch in key):
                yield (*base, "environment", key), "not a valid environment variable name"
        folders = Counter(r.folder for r in comp.repositories if r.folder)
        for i, repo in enumerate(comp.repositories):
            if repo.folder and folders[repo.folder] > 1:
                yield (*base, "repositories", i, "folder"), f"two repositories use folder {repo.folder!r}"
    for index, pkg in enumerate(robot.common_packages):
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


def _folders(robot: Robot, project: Path) -> Iterator[Found]:
    entries: list[tuple[KeyPath, str | None]] = [(("components", i, "folder"), c.folder) for i, c in enumerate(robot.components)]
    entries += [(("common_packages", i, "folder"), p.folder) for i, p in enumerate(robot.common_packages) if p.repo is None]
    for path, rel in entries:
        if rel is None:
            continue
        if Path(rel).is_absolute():
            yield path, f"{rel!r} must be relative to the project folder"
            continue
        target = _inside(project, rel)
        if target is None:
            yield path, f"{rel!r} points outside the project folder"
        elif not target.is_dir():
            yield path, f"folder {rel!r} does not exist"
