"""Write the per-host compose files (``.robocore/compose/<host>.yaml``) and the discovery files (DDS profiles)."""

from __future__ import annotations

from pathlib import Path

from robocore.commands.support.displays import ensure_desktop_password
from robocore.commands.support.state import with_local_build
from robocore.files import PRIVATE, SHARED, write_generated
from robocore.plan import compose, discovery
from robocore.plan.containers import host_specs
from robocore.project import Project


def write_dds_profiles(project: Project) -> list[Path]:
    """Write every file of the robot's discovery kind (DDS profiles); remove stale ones robocore wrote before
    (only those: :func:`~robocore.files.write_generated`); return the paths."""
    files = discovery.for_robot(project.robot).files()
    # the folder is made even when the kind has no files: every component mounts it
    return write_generated(project.dds_dir, files, mode=SHARED)  # read in containers, maybe by another user


def write_compose_files(project: Project, *, tag: str | None = None) -> list[Path]:
    """Write one compose file per host (and the DDS profiles they mount); return the compose paths.

    Compose files hold the containers' environment, so they are mode 0600 whatever the umask. The desktops'
    VNC password is made here too (once): their compose services mount it (:func:`ensure_desktop_password`)."""
    write_dds_profiles(project)
    ensure_desktop_password(project)
    texts: dict[str, str] = {}
    for host in project.robot.hosts:
        # The same labels `run` gives the containers (local components: the build they run).
        specs = with_local_build(project, host, host_specs(project, host.name, tag=tag))
        texts[project.compose_file(host.name).name] = compose.render(project, host.name, tag=tag, specs=specs)
    # they hold the containers' environment (robot.yaml's values, perhaps tokens): for the user's eyes only
    return write_generated(project.compose_dir, texts, mode=PRIVATE)
