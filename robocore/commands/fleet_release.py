"""release --fleet: self-contained images for a fleet, pushed and recorded by digest.

``release --fleet [--tag V]`` checks fleet.yaml with robot.yaml (a Swarm fleet refuses what Swarm
cannot run, before anything is built or pushed), then for each component builds its staged image plus
one layer with its install tree and read-only project files (:mod:`robocore.plan.fleet_release`),
pushes it and the base image of every arch in use to the fleet's registry as ``...:V-<arch>-fleet``,
and writes the release record ``.robocore/releases/V.json`` (0600) naming every image by digest. The
single-robot ``release`` (code-less images, manifest lists) is unchanged.

The fleet engines read a record with :func:`load_release_record` and take each image's digest
reference from :meth:`~robocore.plan.fleet_release.ReleaseRecord.component_ref` and
:meth:`~robocore.plan.fleet_release.ReleaseRecord.base_ref`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

from robocore.commands.release import default_tag, released_images
from robocore.commands.support.arch_checks import refuse_foreign_install
from robocore.commands.support.context import Options
from robocore.commands.support.machine import native_arch
from robocore.config.model import Component, read_only_project_path
from robocore.errors import ConfigError, UnsafePath, UsageError
from robocore.files import PRIVATE, read_project_file, refuse_links_leaving, write_atomic
from robocore.plan import naming
from robocore.plan.fleet import swarm_problems
from robocore.plan.fleet_release import (
    FleetImage,
    FleetReleasePlan,
    FleetSource,
    ReleaseRecord,
    digest_ref,
    layer_context,
    layer_dockerfile,
    layer_files,
    parse_release_record,
    plan_fleet_release,
)
from robocore.project import Project

if TYPE_CHECKING:
    import docker

#: Largest release record read (a record names a few images; anything bigger is not one).
MAX_RECORD_BYTES = 1_000_000


@dataclass(frozen=True)
class FleetRelease:
    """What a fleet release pushed: the record's path and every image by digest."""

    kind: ClassVar[str] = "fleet_release"
    tag: str
    record: str
    components: dict[str, dict[str, str]]
    base: dict[str, str]


def record_path(project: Project, version: str) -> Path:
    """Where the release record of ``version`` is: ``.robocore/releases/<version>.json``."""
    if not naming.is_image_tag(version):
        raise UsageError(f"{version!r} is not a release version (an image tag)")
    return project.releases_dir / f"{version}.json"


def load_release_record(project: Project, version: str) -> ReleaseRecord:
    """The release record of ``version`` made by ``release --fleet --tag V``; UsageError naming the file when it is
    missing, is not a regular file inside the project, or is not a record (it is never half-read)."""
    path = record_path(project, version)
    if not os.path.lexists(path):
        raise UsageError(f"no fleet release {version}: {path} does not exist",
                         hint=f"run `release --fleet --tag {version}` first")
    try:
        raw = read_project_file(path, project.root, limit=MAX_RECORD_BYTES, what="release record")
    except UnsafePath as exc:
        raise UsageError(exc.message, hint="remove it and run `release --fleet` again") from None
    if len(raw) > MAX_RECORD_BYTES:
        raise UsageError(f"{path}: not a release record: larger than {MAX_RECORD_BYTES:,} bytes")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise UsageError(f"{path}: not a release record: not UTF-8") from None
    record = parse_release_record(text, str(path))
    if record.version != version:
        raise UsageError(f"{path}: records release {record.version!r}, not {version!r}")
    return record


def plan_for(project: Project, version: str, registry: str) -> FleetReleasePlan:
    """The images of the fleet release of ``version``: every base of an arch in use, then each component with
    its layer's files (checked: present, inside the project, of its host's arch)."""
    robot = project.robot
    sources: list[FleetSource] = []
    local = {(image.repo, image.arch): image.source for image in released_images(project)}
    base = naming.base_image(robot, project.name)
    sources += [FleetSource("", arch, source, repo) for (repo, arch), source in sorted(local.items()) if repo == base]
    for comp in robot.components:
        host = robot.host(comp.runs_on)
        repo = naming.component_image(robot, project.name, comp.name)
        install = _install_tree(project, comp)
        if install is not None:
            refuse_foreign_install(install, host, comp.name)
        files = layer_files(comp, install, project.root)
        _check_project_files(project, comp)
        source = comp.image or local[(repo, host.arch.value)]
        sources.append(FleetSource(comp.name, host.arch.value, source, repo, files))
    return plan_fleet_release(registry, version, sources)


def _install_tree(project: Project, comp: Component) -> Path | None:
    if not comp.has_workspace:
        return None
    if project.robot.host(comp.runs_on).builds_here:
        raise UsageError(f"component {comp.name}: built on its host (builds_here), so its install tree is not on "
                         "this machine for a fleet image", hint="build it here (remove builds_here) for fleets")
    install = project.build_dir(comp.name) / "install"
    if not install.is_dir():
        raise UsageError(f"component {comp.name}: no install tree at {install}",
                         hint=f"run `build --component {comp.name}` first")
    refuse_links_leaving(install, project.root, what=f"the install tree of component {comp.name}, put in its "
                         "fleet image")
    return install


def _check_project_files(project: Project, comp: Component) -> None:
    """Each read-only project volume of ``comp`` exists and stays in the project (as sync requires)."""
    for index, volume in enumerate(comp.volumes):
        rel = read_only_project_path(volume)
        if rel is None:
            continue
        real = (project.root / rel).resolve()
        if not real.exists():
            raise UsageError(f"component {comp.name}: volumes[{index}]: {project.root / rel} does not exist",
                             hint="create it, or remove the volume: its fleet image carries it")
        if rel == ".." or rel.startswith("../") or (not real.is_relative_to(project.root.resolve())
                                                    and not comp.allow_outside_project):
            raise UnsafePath(f"component {comp.name}: volumes[{index}]: {rel} leads outside the project folder "
                             f"({real}); its fleet image would carry it",
                             hint="move it into the project, or set allow_outside_project: true on the component")
        refuse_links_leaving(project.root / rel, project.root, allowed=comp.allow_outside_project,
                             what=f"read-only volume {volume!r} of component {comp.name}, put in its fleet image")


def release_fleet(options: Options, *, tag: str | None) -> None:
    """Build, push and record by digest the self-contained images of a fleet release (see the module)."""
    project = options.load()
    report = options.report
    if not project.has_fleet:
        raise UsageError(f"release --fleet needs a fleet file: {project.fleet_file} does not exist",
                         hint="copy fleet.example.yaml to fleet.yaml (docs/fleet-file.md)")
    fleet = project.load_fleet()
    problems = swarm_problems(project.robot, fleet, project.robot_file)
    if problems:
        raise ConfigError(problems)
    registry = fleet.registry_for(project.robot)
    assert registry is not None  # the fleet file's checks require one
    version = tag or default_tag(project)
    if not naming.is_image_tag(version):
        raise UsageError(f"{version!r} is not a valid image tag", hint="letters, digits, '_', '.', '-' (max 128)")
    plan = plan_for(project, version, registry)
    path = record_path(project, version)
    if options.dry_run:
        for image in plan.images:
            what = f"{image.source} + one layer ({', '.join(str(f.target) for f in image.layer)})" \
                if image.layer else image.source
            report.out(f"{image.ref} ({image.arch}): {what}")
        report.out(f"# then the digest of each in {path} (0600)")
        return
    from robocore.adapters.docker_hosts import local_client

    project.check_state_links()
    client = local_client(timeout=1800)
    components: dict[str, dict[str, str]] = {}
    bases: dict[str, str] = {}
    try:
        for image in plan.images:
            ref = _build_and_push(client, image)
            (bases if image.is_base else components.setdefault(image.component, {}))[image.arch] = ref
            report.info(f"pushed {ref} ({image.component or 'base'}, {image.arch})")
    finally:
        client.close()
    record = ReleaseRecord(version=version, registry=registry, components=components, base=bases)
    write_atomic(path, record.to_json(), mode=PRIVATE)
    report.add(FleetRelease(tag=version, record=str(path), components=components, base=bases))
    report.info(f"released {version} for the fleet: {path}")


def _build_and_push(client: docker.DockerClient, image: FleetImage) -> str:
    """The image of ``image`` (its source, plus its layer when it has one) tagged as ``image.ref``, pushed; its
    digest reference."""
    from docker.errors import ImageNotFound

    from robocore.adapters.image_builder import build_image, expand
    from robocore.adapters.image_delivery import push_digest
    from robocore.plan.dockerfiles import ImagePlan

    try:
        local = client.images.get(image.source)
    except ImageNotFound:
        raise UsageError(f"image {image.source} does not exist",
                         hint="run `prepare-base` and `stage` first (or pull a component's own image)") from None
    found = str(local.attrs.get("Architecture") or "")
    if found and found != image.arch:
        raise UsageError(f"image {image.source} is of arch {found}, not {image.arch}",
                         hint="run `prepare-base` and `stage` again")
    if image.layer:
        context = layer_context(image.layer)
        plan = ImagePlan(role="component", name=image.target, tag=image.tag, arch=image.arch,
                         dockerfile=layer_dockerfile(str(local.id), image.labels), parent=str(local.id),
                         context=context, component=image.component)
        build_image(client, plan, expand(context), labels={}, native_arch=native_arch())
    else:
        local.tag(image.target, image.tag)
    return digest_ref(image.target, push_digest(client, image.target, image.tag))

