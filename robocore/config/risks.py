"""Settings that are allowed but hand a container (or a file's author) power over a machine.

``privileged: true``, a volume of the host's ``/`` or of the Docker socket, a disk as a device,
an ``ext::`` or local git source, a read-only project volume that leads out of the project: each
has real uses, so none is refused. ``robocore validate`` prints one warning line for each, so that
whoever reviews a robot.yaml (from a colleague, a template, a pull request) sees them.
"""

from __future__ import annotations

import posixpath
from collections.abc import Iterator
from pathlib import Path

from robocore.config.checks import outside_target
from robocore.config.mappings import (
    HOST_FOLDERS,
    SYSTEM_FOLDERS,
    exposes_docker_socket,
    is_block_device,
    is_host_device,
    owns_host_folder,
)
from robocore.config.model import Component, Host, Robot
from robocore.config.values import shown

KeyPath = tuple[str | int, ...]
EPHEMERAL_SAFE_DOMAIN = 101
"""The highest ROS 2 domain whose DDS ports (7400 + 250 D + up to ~250) stay below Linux's ephemeral ports."""
Found = tuple[KeyPath, str]


def risky_settings(robot: Robot, project: Path | None = None) -> list[Found]:
    """One ``(key path, warning)`` per dangerous but allowed setting; ``project`` (resolved) adds the
    volumes that lead outside it."""
    found: list[Found] = []
    for index, comp in enumerate(robot.components):
        base: KeyPath = ("components", index)
        found += [((*base, *key), message) for key, message in _component(comp)]
        if project is not None and comp.allow_outside_project:
            found += [((*base, *key), message) for key, message in _outside_project(comp, project)]
        for i, repo in enumerate(comp.repositories):
            message = _git_warning(repo.protocol, repo.url)
            if message:
                found.append(((*base, "repositories", i, "url"), message))
    if robot.ros_version == 2 and robot.ros_domain_id > EPHEMERAL_SAFE_DOMAIN:
        found.append((("ros_domain_id",), ephemeral_domain(robot.ros_domain_id)))
    for index, host in enumerate(robot.hosts):
        found += [(("hosts", index, *key), message) for key, message in host_risks(host)]
    for index, pkg in enumerate(robot.common_packages):
        protocol = pkg.repo_protocol
        message = _git_warning(protocol, pkg.repo) if protocol and pkg.repo else None
        if message:
            found.append((("common_packages", index, "repo"), message))
    return found


def ephemeral_domain(domain: int) -> str:
    """The warning for a ROS 2 domain above :data:`EPHEMERAL_SAFE_DOMAIN` (robot.yaml's, or a fleet robot's own)."""
    return (f"ROS domain {domain} binds its DDS ports from {7400 + 250 * domain}, in Linux's ephemeral range (32768 "
            f"and up), where any program's outgoing socket may take a port first and a node or discovery server then "
            f"fails to start: use a domain of 0-{EPHEMERAL_SAFE_DOMAIN}")


def host_risks(host: Host) -> Iterator[Found]:
    """The dangerous but allowed settings of one host (of robot.yaml, or fleet.yaml's manager): its daemon reached
    by plain TCP (``insecure``), a system folder as its ``mount_root``."""
    if host.insecure:
        yield (("insecure",), f"host {host.name}: its Docker daemon is reached by plain TCP without authentication: "
               "whoever reaches its port owns the host (use docker: ssh or tls)")
    root = host.mount_root.rstrip("/") or "/" if host.mount_root else None
    if root is not None and (root == "/" or owns_host_folder(root, SYSTEM_FOLDERS) is not None):
        yield ("mount_root",), (f"host {host.name}: mount_root {shown(root)} is a system folder: sync writes releases "
                                "there")


def _component(comp: Component) -> Iterator[Found]:
    host = comp.runs_on
    if comp.privileged:
        yield ("privileged",), f"{comp.name} runs privileged: every device and kernel feature of {host}"
    if comp.desktop is not None and comp.desktop.open:
        where = "127.0.0.1" if comp.desktop.local_only else "every interface"
        yield (("desktop", "open"),
               f"{comp.name} serves its desktop through noVNC on port {comp.desktop.web_port} of {where} of {host}, "
               "without a password (desktop.open: true): whoever reaches it sees and controls the screen (remove "
               "open to ask for the project's VNC password)")
    for i, volume in enumerate(comp.volumes):
        source = volume.split(":")[0]
        if not source.startswith("/"):
            continue
        source = posixpath.normpath(source)
        if source == "/":
            yield ("volumes", i), f"mounts the whole file system of {host} ({shown(volume)})"
        elif exposes_docker_socket(source):
            yield (("volumes", i),
                   f"mounts the Docker socket of {host} ({shown(volume)}): the container controls {host}'s Docker, "
                   f"and so {host}")
        elif owns_host_folder(source) is not None and not volume.endswith(":ro"):
            yield (("volumes", i),
                   f"mounts {owns_host_folder(source)} of {host} writable ({shown(volume)}): the container can "
                   f"change {host} itself")
        elif source in HOST_FOLDERS:  # read-only: a single file (/etc/localtime) is common, a whole folder is not
            yield (("volumes", i), f"mounts all of {source} of {host} ({shown(volume)}): the container reads its "
                   "secrets")
    for i, device in enumerate(comp.devices):
        path = device.split(":")[0]
        if path == "/dev":
            yield ("devices", i), f"passes every device of {host}, its disks included ({shown(device)})"
        elif is_block_device(path):
            yield ("devices", i), f"passes a disk of {host} ({shown(device)}): the container can read and rewrite it"
        elif is_host_device(path):
            yield (("devices", i),
                   f"passes {shown(path)} of {host} (memory, ports or flash): the container can rewrite {host}")


def _outside_project(comp: Component, project: Path) -> Iterator[Found]:
    for i, volume in enumerate(comp.volumes):
        target = outside_target(project, volume)
        if target is not None:
            yield (("volumes", i),
                   f"{shown(volume.split(':')[0])} leads outside the project, to {shown(str(target))}; sync copies "
                   f"it to {comp.runs_on} (allow_outside_project: true)")


def _git_warning(protocol: str, url: str) -> str | None:
    if protocol == "ext":
        return f"{shown(url)} runs a command on this machine at every fetch (allow_protocol: ext)"
    if protocol == "file":
        return f"{shown(url)} copies files of this machine into the image (allow_protocol: file)"
    return None
