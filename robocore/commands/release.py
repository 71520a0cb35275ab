"""release and rollback: versioned images in a registry, and going back to what ran before.

``release [--tag V]`` pushes the base image of each arch in use and every staged component image to
``robot.yaml``'s ``registry`` as ``<registry>/<image>:V-<arch>`` (default V: ``git describe --tags
--always --dirty`` of the project), then one multi-arch name ``<registry>/<image>:V`` per image (a
manifest list, :mod:`robocore.plan.release`). ``run --tag V`` then has each host pull
``<registry>/<image>:V`` for its own arch.

Every successful ``run`` appends what a host now runs (image tag, synced release per
component) to the host's release history (:mod:`robocore.commands.support.state`). ``rollback`` takes
each host back to the entry before the last one: it switches each component's ``current``
symlink back to the release it ran then (still on the host: sync keeps the last
:data:`~robocore.plan.sync.KEEP_RELEASES` releases) and re-runs that host with the tag it ran
then. A rollback is itself recorded, so a second rollback returns to where the first one started.
"""

from __future__ import annotations

import shlex
import subprocess
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

from robocore.commands.run import deploy_host
from robocore.commands.support.context import Options
from robocore.commands.support.hosts import for_each_host, select_hosts
from robocore.commands.support.images import base_arches
from robocore.commands.support.state import history, read_synced, record_run, with_synced_release, write_synced
from robocore.config.model import Host
from robocore.errors import DockerError, GroupError, HostError, RobocoreError, UsageError
from robocore.plan import arches, naming
from robocore.plan.containers import host_specs
from robocore.plan.release import (
    LocalImage,
    Push,
    manifest_create_argv,
    manifest_push_argv,
    plain_http,
    plan_release,
)
from robocore.plan.sync import KEEP_RELEASES
from robocore.project import Project

if TYPE_CHECKING:
    import docker

# $1 = component root, $2 = release id: point current at an existing release, atomically.
_SWITCH_SCRIPT = """\
set -eu
cd -- "$1"
[ -d "releases/$2" ] || { echo "release $2 is no longer on this host" >&2; exit 3; }
rm -f -- .current.tmp
ln -s -- "releases/$2" .current.tmp
mv -T -- .current.tmp current
"""


@dataclass(frozen=True)
class Release:
    """The images a release pushed, under its version."""

    kind: ClassVar[str] = "release"
    tag: str
    pushed: list[str]


@dataclass(frozen=True)
class Rollback:
    """What a host went back to: the tag it runs and each component's release."""

    kind: ClassVar[str] = "rollback"
    host: str
    tag: str | None
    releases: dict[str, str]


# --------------------------------------------------------------------------- release


def default_tag(project: Project) -> str:
    """``git describe --tags --always --dirty`` of the project folder."""
    try:
        proc = subprocess.run(["git", "describe", "--tags", "--always", "--dirty"], cwd=project.root,
                              capture_output=True, text=True, timeout=30, check=False)
    except FileNotFoundError:
        raise UsageError("git is not installed, so there is no default version", hint="pass --tag V") from None
    if proc.returncode != 0:
        raise UsageError(f"{project.root} is not a git repository with a commit, so there is no default version",
                         hint="pass --tag V, or commit the project to git")
    return proc.stdout.strip()


def released_images(project: Project) -> list[LocalImage]:
    """The images of this machine that a release carries: the base of each arch in use and every built
    component image (of its host's arch)."""
    robot = project.robot
    base = naming.base_image(robot, project.name)
    images = [LocalImage(repo=base, arch=arch, source=f"{base}:{arches.base_tag(arch, project.native_arch)}")
              for arch in base_arches(project)]
    for comp in robot.components:
        if not comp.image:
            repo = naming.component_image(robot, project.name, comp.name)
            images.append(LocalImage(repo=repo, arch=robot.host(comp.runs_on).arch.value, source=f"{repo}:latest"))
    return images


def release(options: Options, *, tag: str | None) -> None:
    """Push every image of the project under a version, one per arch, and one multi-arch name per image."""
    project = options.load()
    report = options.report
    robot = project.robot
    if not robot.registry:
        raise UsageError(f"{project.robot_file}: release needs a registry (registry: HOST[:PORT][/PATH])",
                         hint="without a registry, `run` streams images to each host instead")
    version = tag or default_tag(project)
    if not naming.is_image_tag(version):
        raise UsageError(f"{version!r} is not a valid image tag", hint="letters, digits, '_', '.', '-' (max 128)")
    plan = plan_release(robot.registry, version, released_images(project))
    if options.dry_run:
        for push in plan.pushes:
            report.out(f"docker tag {push.source} {push.ref} && docker push {push.ref}")
        for manifest in plan.lists:
            report.out(shlex.join(manifest_create_argv("docker", manifest, insecure=False)))
            report.out(shlex.join(manifest_push_argv("docker", manifest, insecure=False)))
        report.out("# (--insecure is added when this machine's Docker daemon reaches the registry over plain http)")
        return
    from robocore.adapters import docker_manifest
    from robocore.adapters.docker_hosts import local_client

    docker = docker_manifest.docker_cli()
    client = local_client(timeout=1800)
    try:
        insecure = plain_http(robot.registry, client.info().get("RegistryConfig") or {})
        pushed = [_push(client, push, robot.registry) for push in plan.pushes]
    finally:
        client.close()
    for push in plan.pushes:
        report.info(f"pushed {push.ref} ({push.arch})")
    for manifest in plan.lists:
        docker_manifest.run(manifest_create_argv(docker, manifest, insecure=insecure),
                            what=f"manifest list {manifest.ref}")
        docker_manifest.run(manifest_push_argv(docker, manifest, insecure=insecure), what=f"push of {manifest.ref}")
        report.info(f"pushed {manifest.ref}: {', '.join(manifest.members)}")
    report.add(Release(tag=version, pushed=pushed + [m.ref for m in plan.lists]))
    report.info(f"released {version}: deploy it with `run --tag {version}`")


def _push(client: docker.DockerClient, push: Push, registry: str) -> str:
    """Tag one arch's local image for the registry and push it; its reference."""
    from docker.errors import APIError, ImageNotFound

    from robocore.adapters.image_delivery import check_stream

    try:
        image = client.images.get(push.source)
    except ImageNotFound:
        raise UsageError(f"image {push.source} does not exist", hint="run `prepare-base` and `stage` first") from None
    found = str(image.attrs.get("Architecture") or "")
    if found and found != push.arch:
        raise UsageError(f"image {push.source} is of arch {found}, not {push.arch}: not released as {push.ref}",
                         hint="run `prepare-base` and `stage` again")
    image.tag(push.target, push.tag)
    try:
        check_stream(client.images.push(push.target, push.tag, stream=True, decode=True), f"push {push.ref}")
    except APIError as exc:
        raise DockerError(f"push {push.ref} failed: {exc.explanation or exc}",
                          hint=f"is the registry {registry} reachable (and trusted) from this machine?") from None
    return push.ref


# --------------------------------------------------------------------------- rollback


def rollback(options: Options, *, host: str | None) -> None:
    """Return each host (or ``--host``) to the version it ran before its last run."""
    project = options.load()
    report = options.report
    hosts = select_hosts(project, host)
    targets: dict[str, dict[str, Any]] = {}
    for h in hosts:
        runs = history(project, h.name)
        if len(runs) >= 2:
            targets[h.name] = runs[-2]
        elif host:
            raise UsageError(f"host {h.name}: no earlier version recorded in {project.history_file(h.name)}",
                             hint="rollback needs two successful runs of this host")
    if not targets:
        raise UsageError("no host has an earlier version to return to", hint="rollback needs two successful runs")
    chosen = [h for h in hosts if h.name in targets]
    if options.dry_run:
        for h in chosen:
            t = targets[h.name]
            report.notice(f"{h.name}: would run tag {t.get('tag') or 'latest'} with releases "
                          f"{t.get('releases') or '(local build output)'}")
        return

    def work(h: Host) -> Any:
        target = targets[h.name]
        _restore_releases(project, h, target.get("releases", {}))
        tag = target.get("tag")
        specs = with_synced_release(project, h, host_specs(project, h.name, tag=tag))
        outcome = deploy_host(project, h, specs, dry_run=False, report=report)
        record_run(project, h, tag)
        return outcome

    results, failures = for_each_host(chosen, work)
    for name in sorted(results):
        t = targets[name]
        report.add(Rollback(host=name, tag=t.get("tag"), releases=dict(t.get("releases") or {})))
        report.notice(f"{name}: back to tag {t.get('tag') or 'latest'}"
                      + (f", releases {t['releases']}" if t.get("releases") else ""))
    if failures:
        raise GroupError(failures, list(results))


def _restore_releases(project: Project, host: Host, releases: dict[str, str]) -> None:
    """Point each component's ``current`` back at ``releases[component]`` and record it as synced."""
    if host.is_local or not releases:
        return
    from robocore.adapters import ssh
    from robocore.plan.layout import component_root
    from robocore.plan.sync import is_release_id

    state = read_synced(project, host.name)
    for component, release_id in sorted(releases.items()):
        if not is_release_id(release_id):
            raise HostError(f"host {host.name}: history names an invalid release {release_id!r} for {component}")
        root = str(component_root(host, component))
        try:
            ssh.run(host, ["sh", "-c", _SWITCH_SCRIPT, "sh", root, release_id], timeout=60)
        except RobocoreError as exc:
            raise HostError(f"host {host.name}: cannot return {component} to release {release_id}: {exc.message}",
                            hint=f"sync keeps the last {KEEP_RELEASES} releases; older ones are gone") from None
        state[component] = {"release": release_id, "digest": ""}
    write_synced(project, host.name, state)
