"""Where a component's install tree and runtime files are on the machine that runs it.

Local hosts use the dev machine's build output directly; remote hosts use what ``sync``
placed under ``<mount_root>/<component>/current`` (a symlink switched atomically to a
complete release directory, so a container never starts on a half-copied tree). Read-only
project volumes come with the release too, under ``current/files/<project-relative path>``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import PurePosixPath

from robocore.config.model import Host
from robocore.project import Project

#: The live release of a component on a remote host (a symlink), and the folder of project files in it.
CURRENT = "current"
FILES = "files"


@dataclass(frozen=True)
class HostPaths:
    """Host-side paths bind-mounted into a component's container."""

    install: str  # -> naming.CONTAINER_INSTALL
    dds: str  # -> naming.CONTAINER_DDS


def component_root(host: Host, component: str) -> PurePosixPath:
    """``<mount_root>/<component>`` on a remote host."""
    return PurePosixPath(host.deploy_root) / component


def host_paths(project: Project, host: Host, component: str) -> HostPaths:
    """The paths on ``host`` that ``component``'s container mounts."""
    if host.is_local:
        return HostPaths(
            install=f"{project.build_dir(component)}/install",
            dds=str(project.dds_dir),
        )
    current = f"{component_root(host, component)}/{CURRENT}"  # strings: a robot of 10,000 components has 20,000
    return HostPaths(install=f"{current}/install", dds=f"{current}/dds")
