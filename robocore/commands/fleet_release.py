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
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

from robocore.commands.release import default_tag, released_images
from robocore.commands.support.arch_checks import refuse_foreign_install
from robocore.commands.support.context import Options
from robocore.commands.support.fleet_layers import layers_line
from robocore.config.model import Component, read_only_project_path
from robocore.errors import ConfigError, Problem, UnsafePath, UsageError
from robocore.files import NEVER, PRIVATE, is_private, refuse_links_leaving, write_atomic
from robocore.plan import naming
from robocore.plan.fleet import swarm_problems
from robocore.plan.fleet_release import (
    FleetImage,
    FleetReleasePlan,
    FleetSource,
    ReleaseRecord,
    digest_ref,
    layer_files,
    parse_release_record,
    plan_fleet_release,
    record_problems,
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


def load_release_record(project: Project, version: str, registry: str | None) -> ReleaseRecord:
    """The release record of ``version`` made by ``release --fleet --tag V``, believed only when it is this user's
    own and writable by no one else (as the no-op memo), in a ``releases`` folder likewise (one this user widened is
    narrowed), and when every image it names is that image's repository in ``registry`` (the fleet's: fleet.yaml's,
    else robot.yaml's). Anything else is refused in one line per problem naming the record (and its key), never
    half-read: missing, a link, a folder, a FIFO, too big, not JSON, another registry or repository."""
    from robocore.files import check_no_links

    path = record_path(project, version)
    try:
        check_no_links(path)
    except UnsafePath as exc:
        raise UsageError(exc.message, hint="remove it and run `release --fleet` again") from None
    _trust_folder(project.releases_dir)
    if not os.path.lexists(path):
        raise UsageError(f"no fleet release {version}: {path} does not exist",
                         hint=f"run `release --fleet --tag {version}` first")
    raw = _read_record(path)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise UsageError(f"{path}: not a release record: not UTF-8") from None
    record = parse_release_record(text, str(path))
    if record.version != version:
        raise UsageError(f"{path}: records release {record.version!r}, not {version!r}")
    robot = project.robot
    components = {c.name: naming.component_image(robot, project.name, c.name) for c in robot.components}
    found = record_problems(record, registry or "", naming.base_image(robot, project.name), components)
    if found:
        raise ConfigError([Problem(str(path), None, key, message) for key, message in found])
    return record


def _trust_folder(folder: Path) -> None:
    """The ``releases`` folder: this user's (else refused); group- or world-writable bits this user left are
    removed (another user could have put a record there, which the record's own check then refuses)."""
    import stat

    try:
        info = os.lstat(folder)
    except FileNotFoundError:
        return
    if not stat.S_ISDIR(info.st_mode):
        raise UsageError(f"{folder}: is not a folder; robocore keeps its release records in it",
                         hint=f"remove {folder} and run `release --fleet` again")
    if info.st_uid != os.geteuid():
        raise UsageError(f"{folder}: belongs to another user (uid {info.st_uid}); robocore believes only records "
                         "of its own user", hint=f"remove {folder} and run `release --fleet` again")
    if info.st_mode & NEVER:
        os.chmod(folder, stat.S_IMODE(info.st_mode) & ~NEVER)


def _read_record(path: Path) -> bytes:
    """The bytes of the record at ``path``: a regular file of this user that no one else may write, at most
    :data:`MAX_RECORD_BYTES`; a UsageError naming it otherwise (never followed, never blocking)."""
    import stat

    again = "remove it and run `release --fleet` again"
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_NOCTTY)
    except OSError as exc:
        raise UsageError(f"{path}: not a release record: cannot be read: {exc.strerror or exc}", hint=again) from None
    info = os.fstat(fd)
    why = None
    if stat.S_ISDIR(info.st_mode):
        why = "not a release record: a folder"
    elif not stat.S_ISREG(info.st_mode):
        why = "not a release record: not a regular file (a FIFO or a device?)"
    elif not is_private(info):
        whose = f"belongs to another user (uid {info.st_uid})" if info.st_uid != os.geteuid() else \
            f"may be written by group or others (mode {stat.S_IMODE(info.st_mode):04o})"
        why = f"not believed: it {whose}; robocore believes only a record of its own user that no one else may write"
    if why is not None:
        os.close(fd)
        raise UsageError(f"{path}: {why}", hint=again)
    with os.fdopen(fd, "rb") as handle:
        raw = handle.read(MAX_RECORD_BYTES + 1)
    if len(raw) > MAX_RECORD_BYTES:
        raise UsageError(f"{path}: not a release record: larger than {MAX_RECORD_BYTES:,} bytes", hint=again)
    return raw


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
            what = f"{image.source} + {layers_line(image)}" if image.layer else image.source
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
            ref = _build_and_push(client, image, report.info)
            (bases if image.is_base else components.setdefault(image.component, {}))[image.arch] = ref
            report.info(f"pushed {ref} ({image.component or 'base'}, {image.arch})")
    finally:
        client.close()
    record = ReleaseRecord(version=version, registry=registry, components=components, base=bases)
    write_atomic(path, record.to_json(), mode=PRIVATE)
    report.add(FleetRelease(tag=version, record=str(path), components=components, base=bases))
    report.info(f"released {version} for the fleet: {path}")


def _build_and_push(client: docker.DockerClient, image: FleetImage, progress: Callable[[str], None]) -> str:
    """The image of ``image`` (its source, plus its layers when it has files) tagged as ``image.ref``, pushed (its
    progress said every few seconds through ``progress``); its digest reference."""
    from docker.errors import ImageNotFound

    from robocore.adapters.image_delivery import push_digest

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
        from robocore.commands.support.fleet_layers import build_layered

        build_layered(client, image, str(local.id))
    else:
        local.tag(image.target, image.tag)
    return digest_ref(image.target, push_digest(client, image.target, image.tag, progress))

