"""The root image a base is built FROM, one per arch, under its per-arch local name (see :mod:`robocore.plan.arches`).

Order, for the arch asked: the per-arch name itself when it already holds an image of that arch (a root robocore
bootstrapped with the current inputs, or one pulled before); else the upstream reference (``debian:bookworm``,
``ros:<distro>-ros-base`` or ``base.image``) when present locally with that arch, or pulled with that platform,
then tagged with the per-arch name; else, for the wheels and debian bases, a root file system made with
``mmdebstrap --arch`` from a Debian mirror (the air-gapped path), in memory when ``/dev/shm`` has room, and
loaded as the one layer of an image archive that names that arch (see :mod:`robocore.adapters.image_archive`).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from robocore.adapters import image_archive
from robocore.adapters.image_builder import ImageState, image_state
from robocore.errors import BuildError, DockerError, ToolMissing, UsageError
from robocore.files import make_folder
from robocore.plan import arches, naming
from robocore.plan.arches import RootStrap

if TYPE_CHECKING:
    import docker

MIRROR_ENV = "ROBOCORE_DEBIAN_MIRROR"
DEFAULT_MIRROR = "http://deb.debian.org/debian"
#: Role label of a bootstrapped root (its inputs label is :func:`strap_hash`).
ROLE_ROOT = "root"
_MIRROR_SCHEMES = ("http://", "https://", "file:///")
#: Where the bootstrap works (default ``/dev/shm``; empty: the project's cache on disk).
SCRATCH_ENV = "ROBOCORE_ROOTFS_SCRATCH"
#: Free bytes the scratch folder needs: the chroot (~0.3 GB for the wheels root) plus its tarball, with margin.
SCRATCH_NEEDS = 2 << 30


def strap_hash(strap: RootStrap) -> str:
    """The content hash of a bootstrapped root's inputs (arch, variant, packages, excludes)."""
    return "sha256:" + hashlib.sha256(strap.key().encode()).hexdigest()


def made_from(state: ImageState | None, strap: RootStrap) -> bool:
    """Whether ``state`` is a root robocore bootstrapped from ``strap`` (its arch, role and inputs hash)."""
    return (state is not None and state.arch == strap.arch and state.labels.get(naming.LABEL_ROLE) == ROLE_ROOT
            and state.labels.get(naming.LABEL_INPUTS) == strap_hash(strap))


def _usable(state: ImageState | None, arch: str, strap: RootStrap | None) -> bool:
    if state is None or state.arch != arch:
        return False
    made = state.labels.get(naming.LABEL_INPUTS)
    if state.labels.get(naming.LABEL_ROLE) != ROLE_ROOT or made is None:
        return True  # pulled: the base's apt step installs what it lacks
    return strap is not None and made == strap_hash(strap)


def _try_pull(client: docker.DockerClient, ref: str, arch: str) -> ImageState | None:
    from docker.errors import DockerException

    repository, tag = arches.split_reference(ref)
    try:
        if "@" in ref:
            client.images.pull(ref, platform=arches.platform(arch))
        else:
            client.images.pull(repository, tag=tag, platform=arches.platform(arch))
    except DockerException:
        return None
    return image_state(client, ref)


def _tag(client: docker.DockerClient, image_id: str, target: str) -> None:
    repository, tag = arches.split_reference(target)
    client.api.tag(image_id, repository, tag=tag, force=True)


def ensure_root_image(
    client: docker.DockerClient,
    *,
    target: str,
    upstream: str,
    arch: str,
    strap: RootStrap | None,
    work_dir: Path,
    status: Callable[[str], None],
) -> tuple[str, str]:
    """The root image ``target`` (reference, image ID) of ``arch``: kept, taken from ``upstream`` (local or
    pulled with its platform) or, when ``strap`` is given, bootstrapped; DockerError when none can be had."""
    kept = image_state(client, target)
    if _usable(kept, arch, strap):
        assert kept is not None
        return target, kept.id
    found = image_state(client, upstream)
    if found is None or found.arch != arch:
        status(f"pulling {upstream} for {arches.platform(arch)}")
        found = _try_pull(client, upstream, arch)
    if found is not None and found.arch == arch:
        _tag(client, found.id, target)
        return target, found.id
    if strap is None:
        raise DockerError(
            f"robot.yaml: base image {upstream} for {arches.platform(arch)} is not present locally and cannot be "
            "pulled",
            hint=f"pull or docker load it (its {arch} image) on this machine, or use base.kind: debian "
                 "(ROS 1) or wheels (ROS 2, amd64), built from Debian packages",
        )
    status(f"no registry reachable: bootstrapping {target} with mmdebstrap --arch={arch}")
    return target, bootstrap(client, strap, target=target, work_dir=work_dir)


def _mirror() -> str:
    mirror = os.environ.get(MIRROR_ENV, DEFAULT_MIRROR)
    if not mirror.startswith(_MIRROR_SCHEMES) or any(ch.isspace() for ch in mirror):
        raise UsageError(f"{MIRROR_ENV}={mirror!r} is not a mirror URL", hint=f"e.g. {DEFAULT_MIRROR}")
    return mirror


def bootstrap(client: docker.DockerClient, strap: RootStrap, *, target: str, work_dir: Path) -> str:
    """mmdebstrap a Debian 12 root of ``strap.arch`` and build it into the image ``target``; return its ID."""
    if shutil.which("mmdebstrap") is None:
        raise ToolMissing(
            "mmdebstrap is needed to bootstrap the Debian 12 root image of the base (no image could be pulled)",
            hint="sudo apt-get install mmdebstrap (Debian/Ubuntu), or set base.image to a local Debian 12 image",
        )
    mirror = _mirror()
    make_folder(work_dir)
    scratch = scratch_dir()
    env = dict(os.environ)
    if scratch is not None:
        env["TMPDIR"] = scratch  # mmdebstrap's chroot: dpkg's many small writes and syncs go to memory
    with tempfile.TemporaryDirectory(dir=scratch or work_dir, prefix=f"robocore-rootfs-{strap.arch}-") as tmp:
        tarball = Path(tmp).resolve() / "root.tar"
        done = subprocess.run(strap.argv(str(tarball), mirror), capture_output=True, text=True, check=False,
                              env=env)
        if done.returncode != 0:
            tail = "\n".join((done.stderr or done.stdout).strip().splitlines()[-15:])
            raise BuildError(f"mmdebstrap --arch={strap.arch} failed (exit {done.returncode}):\n{tail}",
                             hint=f"check that {mirror} is reachable (set {MIRROR_ENV} for another mirror)"
                             + (", and PyPI (the root's venv)" if strap.venv else "")
                             + ("" if strap.arch == _native() else "; an arch other than this machine's needs "
                                "qemu-user-static registered with binfmt_misc"))
        return image_from_tarball(client, tarball, strap, target=target)


def scratch_dir() -> str | None:
    """A memory-backed folder for the bootstrap's chroot and tarball (``/dev/shm`` when it is a writable tmpfs
    with room to spare), else None (the project's cache on disk is used). Same bytes, fewer disk syncs:
    measured 51 s on disk against 30 s in ``/dev/shm`` for the wheels root (a loaded 2-core machine)."""
    shm = os.environ.get(SCRATCH_ENV, "/dev/shm")
    if not shm:
        return None
    try:
        info = os.statvfs(shm)
    except OSError:
        return None
    if info.f_flag & os.ST_NOEXEC or info.f_bavail * info.f_frsize < SCRATCH_NEEDS:
        return None  # the chroot runs maintainer scripts; a small tmpfs would fail half-way
    if not os.access(shm, os.W_OK | os.X_OK):
        return None
    return shm


def _native() -> str:
    import platform

    from robocore.config.model import docker_arch

    return docker_arch(platform.machine())


def image_from_tarball(client: docker.DockerClient, tarball: Path, strap: RootStrap, *, target: str) -> str:
    """An image of ``strap.arch`` tagged ``target`` made from the root tarball, labelled with the strap's hash and
    with its image settings (:attr:`RootStrap.config`); its ID. The tarball is loaded as the one layer of an archive
    that names its arch (one read after hashing, for any arch: ``docker import`` would label it with the daemon's
    own arch on Docker 20.10)."""
    from docker.errors import DockerException

    labels = {naming.LABEL_ROLE: ROLE_ROOT, naming.LABEL_INPUTS: strap_hash(strap)}
    repository, tag = arches.split_reference(target)
    archive = image_archive.LoadArchive(tarball, reference=f"{repository}:{tag}", arch=strap.arch, labels=labels,
                                        comment=f"robocore: mmdebstrap --arch={strap.arch} {arches.SUITE}",
                                        settings=strap.config)
    try:
        client.images.load(archive)  # raises on an error reported in the load's progress stream
    except DockerException as exc:
        raise DockerError(f"image {target}: the Docker daemon refused the root file system: {exc}") from None
    return _made(client, target, strap.arch)


def _made(client: docker.DockerClient, target: str, arch: str) -> str:
    state = image_state(client, target)
    if state is None or state.arch != arch or state.labels.get(naming.LABEL_ROLE) != ROLE_ROOT:
        raise DockerError(f"the root file system build did not produce {target} for {arches.platform(arch)}")
    return state.id
