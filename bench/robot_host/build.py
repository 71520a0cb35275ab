"""Build the simulated robot host image from zero: mmdebstrap a Debian root, docker import it.

The image runs sshd and dockerd (Debian's docker.io) so that integration suites can reach a
"robot" over ssh:// exactly as robocore reaches a real one. Nothing is pulled from a registry.
The image tag carries a hash of its inputs, so it is built once per machine.

    python bench/robot_host/build.py      # prints the image name
"""

from __future__ import annotations

import hashlib
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPOSITORY = "robocore-test/robot-host"
PACKAGES = [
    "docker.io",
    "openssh-server",
    "rsync",
    "iproute2",
    "procps",
    "ca-certificates",
    "iptables",
    "mount",  # the entry point mounts binfmt_misc: an arm64 host simulated on amd64 shows its qemu entry
]
MIRROR = "http://deb.debian.org/debian"
SUITE = "bookworm"


def image_name() -> str:
    """The tag of the image for the current inputs."""
    digest = hashlib.sha256()
    digest.update(" ".join([SUITE, MIRROR, *PACKAGES]).encode())
    digest.update((HERE / "entrypoint.sh").read_bytes())
    return f"{REPOSITORY}:{digest.hexdigest()[:12]}"


def _exists(name: str) -> bool:
    return subprocess.run(["docker", "image", "inspect", name], capture_output=True).returncode == 0


def ensure_image() -> str:
    """Build the robot host image unless an image with the same inputs exists; return its name."""
    name = image_name()
    if _exists(name):
        return name
    entry = HERE / "entrypoint.sh"
    with tempfile.TemporaryDirectory(prefix="robocore-robot-host-") as tmp:
        root = Path(tmp) / "root.tar"
        subprocess.run(
            [
                "mmdebstrap",
                "--variant=apt",
                "--include=" + ",".join(PACKAGES),
                f"--customize-hook=upload {entry} /usr/local/bin/robot-host-entry",
                '--customize-hook=chmod 755 "$1/usr/local/bin/robot-host-entry"',
                "--customize-hook=rm -rf \"$1\"/var/cache/apt/archives/*.deb \"$1\"/var/lib/apt/lists/*",
                SUITE,
                str(root),
                MIRROR,
            ],
            check=True,
        )
        subprocess.run(
            ["docker", "import", "--change", 'CMD ["/usr/local/bin/robot-host-entry"]', str(root), name],
            check=True,
            stdout=subprocess.DEVNULL,
        )
    return name


if __name__ == "__main__":
    print(ensure_image())
    sys.exit(0)
