#!/usr/bin/env python3
"""Run inside a stand-in's build: what the ROS apt repository and the rosdistro repository give the real images.

- ``/var/lib/ros-standin-apt``: a flat apt repository (listed in ``/etc/apt/sources.list.d/ros-standin.list``) with
  ``python3-colcon-common-extensions`` (its real dependencies, Debian 12's colcon packages) and, for ROS 2,
  ``ros-<distro>-ros-base``, which provides ``ros-<distro>-<package>`` for every package of the ament index under
  the prefix (the files themselves were installed from PyPI wheels);
- ``/etc/ros/rosdistro``: a rosdistro index (``ROSDISTRO_INDEX_URL``) and the distribution file, released for
  Debian 12, with (ROS 2) those packages, so that ``rosdep`` resolves ``rclpy`` to ``ros-<distro>-rclpy`` as it does
  on the real images.

Usage: make_ros_repo.py DISTRO ROS_VERSION PREFIX
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path("/var/lib/ros-standin-apt")
ROSDISTRO = Path("/etc/ros/rosdistro")
#: python3-colcon-common-extensions' dependencies that Debian 12 has (it has no colcon-powershell), and the
#: ``colcon`` command (Debian has it in a package of its own).
COLCON = ("colcon", "python3-colcon-argcomplete", "python3-colcon-bash", "python3-colcon-cd", "python3-colcon-cmake",
          "python3-colcon-core", "python3-colcon-defaults", "python3-colcon-devtools",
          "python3-colcon-library-path", "python3-colcon-metadata", "python3-colcon-notification",
          "python3-colcon-output", "python3-colcon-package-information", "python3-colcon-package-selection",
          "python3-colcon-parallel-executor", "python3-colcon-python-setup-py", "python3-colcon-recursive-crawl",
          "python3-colcon-ros", "python3-colcon-test-result", "python3-colcon-zsh")


def deb(name: str, description: str, **fields: str) -> Path:
    """A package with no files, only relations (``Depends``, ``Provides``), built with dpkg-deb."""
    arch = subprocess.run(["dpkg", "--print-architecture"], capture_output=True, text=True, check=True).stdout.strip()
    with tempfile.TemporaryDirectory() as tmp:
        control = Path(tmp, "DEBIAN")
        control.mkdir()
        lines = [f"Package: {name}", "Version: 0.0.0-standin", f"Architecture: {arch}",
                 "Maintainer: robocore integration tests <tests@robocore.invalid>", "Section: misc",
                 "Priority: optional", *(f"{key}: {value}" for key, value in fields.items()),
                 f"Description: {description}"]
        (control / "control").write_text("\n".join(lines) + "\n")
        out = REPO / f"{name}.deb"
        subprocess.run(["dpkg-deb", "--root-owner-group", "-Zgzip", "--build", tmp, str(out)], check=True,
                       capture_output=True)
    return out


def packages_index(debs: list[Path]) -> str:
    """The repository's Packages file: each package's control fields plus where and what its file is."""
    stanzas = []
    for path in debs:
        control = subprocess.run(["dpkg-deb", "-f", str(path)], capture_output=True, text=True, check=True).stdout
        data = path.read_bytes()
        stanzas.append(control.rstrip("\n") + f"\nFilename: ./{path.name}\nSize: {len(data)}\n"
                       f"SHA256: {hashlib.sha256(data).hexdigest()}\n")
    return "\n".join(stanzas)


def ament_packages(prefix: Path) -> list[str]:
    """The ROS 2 packages installed under ``prefix`` (its ament index)."""
    index = prefix / "share" / "ament_index" / "resource_index" / "packages"
    return sorted(os.listdir(index)) if index.is_dir() else []


def main(distro: str, ros_version: str, prefix: str) -> int:
    REPO.mkdir(parents=True, exist_ok=True)
    ros = ament_packages(Path(prefix)) if ros_version == "2" else []
    debs = [deb("python3-colcon-common-extensions", "colcon and its common extensions (stand-in: Debian 12's)",
                Depends=", ".join(COLCON))]
    if ros:
        provided = ", ".join(f"ros-{distro}-{name.replace('_', '-')}" for name in ros)
        debs.append(deb(f"ros-{distro}-ros-base", f"ROS {distro} (stand-in: installed from PyPI wheels)",
                        Provides=provided))
    (REPO / "Packages").write_text(packages_index(debs))
    Path("/etc/apt/sources.list.d/ros-standin.list").write_text(f"deb [trusted=yes] file:{REPO} ./\n")
    ROSDISTRO.joinpath(distro).mkdir(parents=True, exist_ok=True)
    kind = "ros1" if ros_version == "1" else "ros2"
    (ROSDISTRO / "index-v4.yaml").write_text(
        "%YAML 1.1\n---\ntype: index\nversion: 4\ndistributions:\n"
        f"  {distro}:\n    distribution: [{distro}/distribution.yaml]\n    distribution_status: active\n"
        f"    distribution_type: {kind}\n    python_version: 3\n")
    repositories = "".join(f"  {name}:\n    release:\n      url: file://{prefix}\n" for name in ros)
    (ROSDISTRO / distro / "distribution.yaml").write_text(
        "%YAML 1.1\n---\ntype: distribution\nversion: 2\nrelease_platforms:\n  debian: [bookworm]\n"
        + ("repositories:\n" + repositories if repositories else "repositories: {}\n"))
    print(f"stand-in ROS repositories: {len(ros)} ROS packages, {len(debs)} apt packages")
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))
