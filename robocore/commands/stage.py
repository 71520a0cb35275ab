"""stage: one image per component (its dependencies, never its code), built side by side, then the
per-host compose files.

A component image is rebuilt only when its inputs hash changes; it hashes on the base's inputs
hash, so an unchanged base leaves it unchanged. ``--refresh`` only rewrites the compose files.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import TYPE_CHECKING

from robocore.commands.prepare_base import plan_base
from robocore.commands.support.composefiles import write_compose_files
from robocore.commands.support.context import DRY_RUN_UNKNOWN, Options
from robocore.commands.support.images import (
    Planned,
    allowed_protocol,
    base_arches,
    decide,
    fetch_source,
    planned,
    run_builds,
    show_plan,
    triage,
)
from robocore.commands.support.machine import check_emulation, local_docker, native_arch
from robocore.commands.support.reporting import Outcome, Reporter, report_outcomes
from robocore.commands.support.workspace import (
    check_workspace,
    selected_components,
    wheels_cmake_packages,
    workspace_files,
)
from robocore.config.model import BaseKind, Component
from robocore.errors import BuildError
from robocore.plan import arches, dockerfiles, naming
from robocore.plan.dockerfiles import ContextEntry, ImagePlan
from robocore.project import Project

if TYPE_CHECKING:
    import docker


def package_xmls(ws: Path) -> list[str]:
    """Workspace-relative paths of every package.xml of a component's workspace."""
    return [rel for rel, _ in workspace_files(ws) if rel.rsplit("/", 1)[-1] == "package.xml"]


@dataclass(frozen=True)
class BaseRef:
    """A built base image as components see it: reference, arch and inputs hash."""

    ref: str
    arch: str
    inputs: str


def plan_component(project: Project, component: Component, base: BaseRef, *, dry_run: bool = False,
                   refresh_sources: bool = False) -> Planned:
    """The staged image plan of ``component`` on top of ``base``.

    Components hash on the base's inputs hash: an unchanged base leaves them unchanged.
    """
    robot = project.robot
    entries: list[ContextEntry] = []
    xmls: list[str] = []
    if robot.base.kind is BaseKind.official and component.folder:
        ws = check_workspace(project, component)
        for rel in package_xmls(ws):
            dest = dockerfiles.rosdep_dest(PurePosixPath(rel))
            entries.append(ContextEntry(dest, source=ws / rel))
            xmls.append(dest)
    folders: list[str] = []
    known = True
    for repo in component.repositories:
        folder = dockerfiles.repo_folder(repo)
        source = fetch_source(project, repo.url, repo.version, allowed_protocol(repo), refresh=refresh_sources,
                              dry_run=dry_run)
        if source is None:
            known = False  # a dry run before the first fetch
        else:
            entries.append(ContextEntry(f"repos/{folder}", source=source))
        folders.append(folder)
    sources = [e.source for e in entries if e.dest.startswith("repos/") and e.source]
    if component.folder and robot.base.kind is BaseKind.wheels:
        sources.append(check_workspace(project, component))
    cmake = wheels_cmake_packages(project, sources)
    dockerfile = dockerfiles.component_dockerfile(robot, component, base_ref=base.ref, package_xmls=xmls,
                                                  repo_folders=folders, cmake=cmake)
    plan = ImagePlan(role="component", name=naming.component_image(robot, project.name, component.name),
                     tag="latest", arch=base.arch, dockerfile=dockerfile, parent=base.ref,
                     context=tuple(entries), component=component.name)
    return planned(project, plan, base.inputs, known=known)


def existing_base(project: Project, client: docker.DockerClient | None, arch: str, *,
                  dry_run: bool = False) -> BaseRef:
    """The built base image for ``arch`` (stage does not rebuild it: that is prepare-base's job); without
    a client (a dry run) its inputs are :data:`DRY_RUN_UNKNOWN`."""
    from robocore.adapters.image_builder import image_state

    ref = f"{naming.base_image(project.robot, project.name)}:{arches.base_tag(arch, native_arch())}"
    if client is None:
        return BaseRef(ref=ref, arch=arch, inputs=DRY_RUN_UNKNOWN)
    state = image_state(client, ref)
    if state is None or naming.LABEL_INPUTS not in state.labels:
        if dry_run:
            return BaseRef(ref=ref, arch=arch, inputs="(base not built yet: run prepare-base first)")
        raise BuildError(f"no base image {ref}", hint="run `prepare-base` first")
    return BaseRef(ref=ref, arch=arch, inputs=state.labels[naming.LABEL_INPUTS])


def _warn_stale_base(project: Project, client: docker.DockerClient, bases: dict[str, BaseRef],
                     report: Reporter) -> None:
    """Say so when robot.yaml or common packages changed since the base was built."""
    from rich.markup import escape

    if any(pkg.repo for pkg in project.robot.common_packages):
        return  # git sources are only fetched by prepare-base
    for arch, base in bases.items():
        current = plan_base(project, client, arch, dry_run=True)
        if current.inputs != base.inputs and not base.inputs.startswith("("):
            report.info(f"[yellow]warning[/]: the inputs of {escape(base.ref)} changed since it was built "
                        "(common packages or base settings); run prepare-base to rebuild it", markup=True)


def _write_compose_files(project: Project, report: Reporter) -> None:
    for path in write_compose_files(project):
        report.info(f"wrote {path.relative_to(project.root)}")


def stage(options: Options, *, refresh: bool, component: str | None, force: bool) -> None:
    """Build component images (in parallel), then write the per-host compose files."""
    project = options.load()
    report = options.report
    if refresh:
        if options.dry_run:
            report.plain("would rewrite the per-host compose files")
        else:
            _write_compose_files(project, report)
        return
    comps = selected_components(project, component)
    dockerfiles.refuse_robot_shape(project)
    client = None if options.dry_run else local_docker()  # a dry run contacts no daemon
    from robocore.adapters.image_builder import image_state

    outcomes: list[Outcome] = []
    work: list[tuple[Planned, str]] = []
    try:
        bases = {arch: existing_base(project, client, arch, dry_run=options.dry_run)
                 for arch in base_arches(project, comps)}
        if client is not None:
            _warn_stale_base(project, client, bases, report)
        for comp in comps:
            base = bases[project.robot.host(comp.runs_on).arch.value]
            if not options.dry_run:
                check_emulation(base.arch, native_arch(), f"component {comp.name} (host {comp.runs_on})")
            image = plan_component(project, comp, base, dry_run=options.dry_run, refresh_sources=force)
            reason = decide(image_state(client, image.plan.ref) if client else None, image, force=force)
            if options.dry_run:
                show_plan(report, image, reason)
                if comp.repositories:
                    from robocore.adapters import vcs

                    folders = {i: dockerfiles.repo_folder(r) for i, r in enumerate(comp.repositories)}
                    report.plain(f"# {comp.name}: repositories (vcstool .repos), fetched on this machine into "
                                 "repos/\n" + vcs.repos_file(comp.repositories, folders))
            triage(image, reason, options.dry_run, outcomes, work)
    finally:
        if client is not None:
            client.close()
    outcomes += run_builds(report, work, parallel=True)
    if options.dry_run:
        report.plain("then: rewrite the per-host compose files")
    else:
        _write_compose_files(project, report)
    report_outcomes(report, outcomes)
