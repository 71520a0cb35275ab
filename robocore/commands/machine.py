"""The developer's machine as the image and colcon steps need it: its arch, whether it can run another
arch's binaries, its trust store, and its Docker daemon."""

from __future__ import annotations

import os
import platform as host_platform
from pathlib import Path
from typing import TYPE_CHECKING

from robocore.config.model import docker_arch, machine_arch
from robocore.errors import ToolMissing

if TYPE_CHECKING:
    import docker

BINFMT_DIR = Path("/proc/sys/fs/binfmt_misc")
#: Image builds, colcon builds and test runs at once on this machine.
MAX_PARALLEL = 4


def native_arch() -> str:
    """The dev machine's arch in Docker terms."""
    return docker_arch(host_platform.machine())


def check_emulation(arch: str, native: str, who: str) -> None:
    """Raise ToolMissing when ``arch`` binaries cannot run here (no binfmt/qemu registration)."""
    if arch == native:
        return
    qemu = machine_arch(arch)
    if (BINFMT_DIR / f"qemu-{qemu}").exists():
        return
    raise ToolMissing(
        f"{who} needs {arch} images but this machine is {native} and cannot run {arch} binaries "
        f"({BINFMT_DIR}/qemu-{qemu} is missing)",
        hint=f"sudo apt-get install qemu-user-static binfmt-support (registers qemu-{qemu} with binfmt_misc), "
        f"or run `docker run --privileged --rm tonistiigi/binfmt --install {arch}`",
    )


def find_ca_bundle() -> Path | None:
    """The dev machine's trust store file (a public CA bundle plus any proxy CA), if any."""
    import ssl

    candidates = [os.environ.get(name) for name in ("REQUESTS_CA_BUNDLE", "PIP_CERT", "SSL_CERT_FILE")]
    paths = ssl.get_default_verify_paths()
    candidates += [paths.cafile, paths.openssl_cafile]
    for candidate in candidates:
        if candidate and Path(candidate).is_file():
            return Path(candidate)
    return None


def local_docker() -> docker.DockerClient:
    """The dev machine's Docker daemon, with a timeout long enough for image builds and colcon runs."""
    from robocore.adapters.docker_hosts import local_client

    return local_client(timeout=3600)
