"""The Debian 12 root image of the wheels base: found locally, pulled, or bootstrapped.

Order: ``base.image`` when given (local, else pulled); else an image robocore bootstrapped
before or ``debian:bookworm`` if present; else ``debian:bookworm`` pulled; else a root file
system made with mmdebstrap from a Debian mirror and ``docker import``-ed (the air-gapped path).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from robocore.adapters.image_builder import image_state
from robocore.errors import BuildError, DockerError, ToolMissing
from robocore.files import make_folder

if TYPE_CHECKING:
    import docker

BOOTSTRAPPED = "robocore/debian:bookworm"
UPSTREAM = "debian:bookworm"
MIRROR_ENV = "ROBOCORE_DEBIAN_MIRROR"
DEFAULT_MIRROR = "http://deb.debian.org/debian"
INCLUDE = "python3,python3-venv,ca-certificates,procps"


def _try_pull(client: docker.DockerClient, ref: str, platform: str | None) -> bool:
    from docker.errors import DockerException

    repository, _, tag = ref.rpartition(":") if ":" in ref.rsplit("/", 1)[-1] else (ref, "", "latest")
    try:
        client.images.pull(repository, tag=tag or "latest", platform=platform)
    except DockerException:
        return False
    return image_state(client, ref) is not None


def ensure_root_image(
    client: docker.DockerClient,
    override: str | None,
    *,
    work_dir: Path,
    status: Callable[[str], None],
) -> tuple[str, str]:
    """The root image (reference, image ID) of the wheels base, bootstrapping it if need be."""
    if override:
        state = image_state(client, override)
        if state is None and _try_pull(client, override, None):
            state = image_state(client, override)
        if state is None:
            raise DockerError(
                f"robot.yaml: base.image {override!r} is not present locally and cannot be pulled",
                hint="docker load/import it, or remove base.image to let robocore bootstrap Debian 12",
            )
        return override, state.id
    for ref in (BOOTSTRAPPED, UPSTREAM):
        state = image_state(client, ref)
        if state is not None:
            return ref, state.id
    status(f"pulling {UPSTREAM}")
    if _try_pull(client, UPSTREAM, None):
        state = image_state(client, UPSTREAM)
        if state is not None:
            return UPSTREAM, state.id
    status(f"no registry reachable: bootstrapping {BOOTSTRAPPED} with mmdebstrap")
    return BOOTSTRAPPED, bootstrap(client, work_dir=work_dir)


def bootstrap(client: docker.DockerClient, *, work_dir: Path) -> str:
    """mmdebstrap a Debian 12 root file system and import it as :data:`BOOTSTRAPPED`; return its ID."""
    from docker.errors import DockerException

    if shutil.which("mmdebstrap") is None:
        raise ToolMissing(
            "mmdebstrap is needed to bootstrap the Debian 12 root image of the wheels base (no image could be pulled)",
            hint="sudo apt-get install mmdebstrap (Debian/Ubuntu), or set base.image to a local Debian 12 image",
        )
    mirror = os.environ.get(MIRROR_ENV, DEFAULT_MIRROR)
    make_folder(work_dir)
    with tempfile.TemporaryDirectory(dir=work_dir, prefix="rootfs-") as tmp:
        tarball = Path(tmp) / "root.tar"
        argv = ["mmdebstrap", "--variant=apt", f"--include={INCLUDE}", "bookworm", str(tarball), mirror]
        done = subprocess.run(argv, capture_output=True, text=True, check=False)
        if done.returncode != 0:
            tail = "\n".join((done.stderr or done.stdout).strip().splitlines()[-15:])
            raise BuildError(f"mmdebstrap failed (exit {done.returncode}):\n{tail}",
                             hint=f"check that {mirror} is reachable (set {MIRROR_ENV} for another mirror)")
        repository, _, tag = BOOTSTRAPPED.rpartition(":")
        try:
            with tarball.open("rb") as handle:
                client.api.import_image_from_data(handle, repository=repository, tag=tag)
        except DockerException as exc:
            raise DockerError(f"docker import of the Debian root file system failed: {exc}") from None
    state = image_state(client, BOOTSTRAPPED)
    if state is None:
        raise DockerError(f"docker import did not produce {BOOTSTRAPPED}")
    return state.id
