"""Write the per-host compose files (``.robocore/compose/<host>.yaml``) and the discovery files (DDS profiles)."""

from __future__ import annotations

from pathlib import Path

from robocore.commands.state import with_local_build
from robocore.files import PRIVATE, write_atomic
from robocore.plan import compose, discovery
from robocore.plan.containers import host_specs
from robocore.project import Project


def write_dds_profiles(project: Project) -> list[Path]:
    """Write every file of the robot's discovery kind (DDS profiles); remove stale ones robocore wrote before;
    return the paths."""
    folder = project.dds_dir
    files = discovery.for_robot(project.robot).files()
    folder.mkdir(parents=True, exist_ok=True)  # mounted by every component, even when the kind has no files
    paths = []
    for name, text in files.items():
        path = folder / name
        write_atomic(path, text)
        paths.append(path)
    for stale in folder.iterdir():  # hidden files are other writers' temp files
        if stale.is_file() and not stale.name.startswith(".") and stale.name not in files:
            stale.unlink()
    return paths


def write_compose_files(project: Project, *, tag: str | None = None) -> list[Path]:
    """Write one compose file per host (and the DDS profiles they mount); return the compose paths.

    Compose files hold the containers' environment, so they are mode 0600 whatever the umask."""
    write_dds_profiles(project)
    paths = []
    for host in project.robot.hosts:
        path = project.compose_file(host.name)
        # The same labels `run` gives the containers (local components: the build they run).
        specs = with_local_build(project, host, host_specs(project, host.name, tag=tag))
        # they hold the containers' environment (robot.yaml's values, perhaps tokens): for the user's eyes only
        write_atomic(path, compose.render(project, host.name, tag=tag, specs=specs), mode=PRIVATE)
        paths.append(path)
    known = {p.name for p in paths}
    for stale in project.compose_dir.glob("*.yaml"):
        if stale.name not in known:
            stale.unlink()
    return paths
