"""The official base (``base: official``) on arm64: noetic's stand-in for linux/arm64, on this amd64 machine (qemu).

The arm64 stand-in of ``ros:noetic-ros-base`` (:mod:`official_standins`) is built FROM the arm64 Debian root the
arm64 suites bootstrap (:mod:`arm64_project`; this module runs after them, ``lanes.LAST``), and takes the name
``ros:noetic-ros-base`` as ``docker pull --platform linux/arm64`` would. robocore's ``prepare-base`` then resolves
the arm64 root from that name (its per-arch name ``robocore/arm64/ros:noetic-ros-base`` removed first).

:mod:`arm64_project` makes the stand-in, and the project's base and talker image (``prepare-base`` and ``stage`` of a
copy of it), in the background while the other suites run, as it does for the other arm64 suites: this module's
``prepare-base`` and ``stage`` then find them current by their content hash, and only ``build`` runs under emulation
here. Nothing depends on that head start: without it, they are built here.

The template's noetic project on one arm64 host (its ROS master there too): ``prepare-base`` makes the arm64 base on
the stand-in (colcon from the stand-in's ROS apt repository, rosdep's offline database, the common package built
under emulation), ``stage`` the talker's arm64 image through rosdep, ``build`` compiles the roscpp talker for arm64:
its install tree holds an aarch64 ELF.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import lanes
import official_standins
import pytest
from deploy_helpers import free_tcp_port, remove_project_containers

from robocore.plan import arches

if TYPE_CHECKING:
    from conftest import RobocoreCli

pytestmark = [pytest.mark.docker, pytest.mark.timeout(3000), pytest.mark.usefixtures("official_names")]

NAME = official_standins.ARM64_PROJECT



@pytest.fixture(scope="module")
def arm64_official(arm64_images: None, docker_client: Any, run_robocore: RobocoreCli) -> Iterator[Path]:
    """The noetic project (base: official) on one arm64 host, after prepare-base, and stage and build of the talker."""
    arm64 = official_standins.Standin("noetic", "arm64")
    arm64_id = official_standins.ensure(docker_client, arm64, say=print)
    official_standins.forget_pinned(docker_client, arm64)
    parent = Path(tempfile.mkdtemp(prefix="robocore-it-"))
    root = parent / NAME
    run_robocore(None, "init", str(root), "--defaults", "--distro", "noetic")
    official_standins.arm64_project(root, domain=lanes.new_domain(), port=free_tcp_port())
    timings = {}
    for step, extra in (("prepare-base", ()), ("stage", ("--component", "talker")),
                        ("build", ("--component", "talker"))):
        started = time.monotonic()
        run_robocore(root, step, "--quiet", *extra)
        timings[step] = round(time.monotonic() - started, 1)
    print("official arm64 set-up (s):", timings)
    assert docker_client.images.get(arm64.pinned).id == arm64_id
    yield root
    remove_project_containers(docker_client, NAME)
    shutil.rmtree(parent, ignore_errors=True)


def test_the_arm64_talker_is_built_on_the_official_arm64_base(arm64_official: Path, docker_client: Any) -> None:
    images = {ref: docker_client.images.get(ref).attrs["Architecture"] for ref in (
        "robocore/arm64/ros:noetic-ros-base", f"{NAME}-base:latest-arm64", f"{NAME}-talker:latest")}
    assert set(images.values()) == {"arm64"}, images
    labels = docker_client.images.get(f"{NAME}-base:latest-arm64").attrs["Config"]["Labels"]
    assert labels.get(official_standins.LABEL), labels  # built FROM the stand-in
    machine = docker_client.containers.run(f"{NAME}-talker:latest", ["uname", "-m"], remove=True,
                                           platform="linux/arm64").decode().strip()
    assert machine == "aarch64"
    install = arm64_official / ".robocore" / "build" / "talker" / "install"
    elves = [p for p in install.rglob("talker") if p.is_file() and not p.is_symlink()
             and arches.elf_arch(p.read_bytes()[:20]) is not None]
    assert [arches.elf_arch(p.read_bytes()[:20]) for p in elves] == ["arm64"], elves
    assert (install / arches.INSTALL_ARCH_FILE).read_text().strip() == "arm64"
