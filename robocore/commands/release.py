"""release: versioned images in a registry (``rollback`` goes back to what ran before:
:mod:`robocore.commands.rollback`).

``release [--tag V]`` pushes the base image of each arch in use and every staged component image to
``robot.yaml``'s ``registry`` as ``<registry>/<image>:V-<arch>`` (default V: ``git describe --tags
--always --dirty`` of the project), then one multi-arch name ``<registry>/<image>:V`` per image (a
manifest list, :mod:`robocore.plan.release`). ``run --tag V`` then has each host pull
``<registry>/<image>:V`` for its own arch.
"""

from __future__ import annotations

import shlex
import subprocess
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from robocore.commands.support.context import Options
from robocore.commands.support.images import base_arches
from robocore.errors import DockerError, UsageError
from robocore.plan import arches, naming
from robocore.plan.release import (
    LocalImage,
    Push,
    manifest_create_argv,
    manifest_push_argv,
    plain_http,
    plan_release,
)
from robocore.project import Project

if TYPE_CHECKING:
    import docker

@dataclass(frozen=True)
class Release:
    """The images a release pushed, under its version."""

    kind: ClassVar[str] = "release"
    tag: str
    pushed: list[str]


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
