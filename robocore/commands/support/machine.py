"""The developer's machine as the image and colcon steps need it: its arch, whether it can run another
arch's binaries, its trust store, and its Docker daemon."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

from robocore.config.model import kernel_arch
from robocore.errors import ToolMissing
from robocore.project import this_machine_arch

if TYPE_CHECKING:
    import docker

BINFMT_DIR = Path("/proc/sys/fs/binfmt_misc")
#: Image builds, colcon builds and test runs at once on this machine.
MAX_PARALLEL = 4


def native_arch() -> str:
    """The dev machine's arch in Docker terms."""
    return this_machine_arch()


def emulation_hint(arch: str) -> str:
    """What to run, as root, so that a Linux machine runs ``arch`` binaries through qemu (docs/arm64.md)."""
    qemu = f"qemu-{kernel_arch(arch)}"
    return (f"as root: apt-get install qemu-user-static, then mount -t binfmt_misc binfmt_misc {BINFMT_DIR} "
            f"(if {BINFMT_DIR}/register is missing) and grep '^:{qemu}:' /usr/lib/binfmt.d/{qemu}.conf > "
            f"{BINFMT_DIR}/register (systemd machines: systemctl restart systemd-binfmt)")


def binfmt_problem(text: str | None) -> str | None:
    """Why a binfmt_misc entry's text (None: no entry) does not run foreign binaries in containers; None if it does.

    Containers need the F flag: the interpreter is opened at registration, so no qemu file is needed in the image.
    """
    if text is None:
        return "is not registered"
    if not text.startswith("enabled"):
        return "is disabled"
    flags = next((line.split(":", 1)[1].strip() for line in text.splitlines() if line.startswith("flags:")), "")
    return None if "F" in flags else f"lacks the F flag (flags: {flags or 'none'})"


def check_emulation(arch: str, native: str, who: str) -> None:
    """Raise ToolMissing when ``arch`` binaries cannot run in this machine's containers (no qemu registration)."""
    if arch == native:
        return
    entry = BINFMT_DIR / f"qemu-{kernel_arch(arch)}"
    try:
        text: str | None = entry.read_text()
    except OSError:
        text = None
    why = binfmt_problem(text)
    if why is None:
        return
    raise ToolMissing(
        f"{who} needs {arch} images but this machine is {native} and cannot run {arch} binaries in containers "
        f"({entry} {why})",
        hint=emulation_hint(arch),
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
