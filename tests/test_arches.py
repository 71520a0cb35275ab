"""Per-arch plans (robocore.plan.arches): names, roots, bootstraps, ELF headers, and golden per-arch plans of the
official and debian bases on amd64 and arm64 (set UPDATE_GOLDEN=1 to rewrite the goldens)."""

from __future__ import annotations

import struct

import pytest
from golden_files import check_golden

from robocore.config.loader import parse_robot_text
from robocore.config.model import BaseKind, Robot
from robocore.plan import arches, dockerfiles

MIXED = """\
ros_distro: noetic
base:
  kind: {kind}
hosts:
  - name: jetson
    ip: 192.168.1.20
    arch: arm64
  - name: ipc
    ip: 192.168.1.10
components:
  - name: talker
    folder: components/talker
    runs_on: jetson
  - name: listener
    folder: components/listener
    runs_on: ipc
"""


def _robot(kind: str) -> Robot:
    return parse_robot_text(MIXED.format(kind=kind))


@pytest.mark.parametrize("kind", ["official", "debian"])
@pytest.mark.parametrize("native", ["amd64", "arm64"])
def test_per_arch_plans_golden(kind: str, native: str) -> None:
    """Both arches of a mixed robot, seen from an amd64 and from an arm64 dev machine: roots, bases, ccache,
    and the base Dockerfile each arch is built from."""
    robot = _robot(kind)
    parts = []
    for arch in ("amd64", "arm64"):
        root = arches.base_root(robot, arch)
        dockerfile = dockerfiles.base_dockerfile(robot, root_image=root, has_ca=False, common=[])
        parts += [f"arch {arch} [{arches.platform(arch)}]",
                  f"  root: {root} (local, else {arches.upstream_root(robot)} pulled for {arches.platform(arch)})",
                  f"  base tag: {arches.base_tag(arch, native)}", dockerfile]
    check_golden(f"arches/{kind}-noetic-on-{native}.txt", "\n".join(parts))


def test_two_arches_never_share_a_name() -> None:
    for kind in ("official", "debian"):
        robot = _robot(kind)
        amd, arm = arches.base_root(robot, "amd64"), arches.base_root(robot, "arm64")
        assert arm.startswith("robocore/arm64/") and amd.startswith("robocore/amd64/")
        for native in ("amd64", "arm64"):
            assert arches.base_tag("amd64", native) != arches.base_tag("arm64", native)
        assert (arches.platform("amd64"), arches.platform("arm64")) == ("linux/amd64", "linux/arm64")
    assert arches.root_image(BaseKind.debian, "arm64") == "robocore/arm64/debian:bookworm-debian"


@pytest.mark.parametrize(("ref", "pinned"), [
    ("ros:noetic-ros-base", "robocore/arm64/ros:noetic-ros-base"),
    ("debian", "robocore/arm64/debian:latest"),
    ("registry.local:5000/team/ros:1.2", "robocore/arm64/registry.local-5000/team/ros:1.2"),
    ("Team/Img@sha256:abcdef", "robocore/arm64/team/img:sha256-abcdef"),
])
def test_pinned_names_carry_the_arch(ref: str, pinned: str) -> None:
    assert arches.pinned_image(ref, "arm64") == pinned


def test_root_strap_content_differs_per_arch_and_argv_has_no_option_from_inputs() -> None:
    amd = arches.root_strap(BaseKind.debian, "amd64", dockerfiles.DEBIAN_APT)
    arm = arches.root_strap(BaseKind.debian, "arm64", dockerfiles.DEBIAN_APT)
    assert amd.key() != arm.key() and amd.packages == arm.packages
    argv = arm.argv("/tmp/x/root.tar", "http://deb.debian.org/debian")
    assert argv[:3] == ["mmdebstrap", "--arch=arm64", "--variant=apt"]
    assert argv[-3:] == ["bookworm", "/tmp/x/root.tar", "http://deb.debian.org/debian"]
    assert "ros-core-dev" in argv[3] and "g++" in argv[3]


def test_root_strap_byte_compiles_once_at_the_end() -> None:
    strap = arches.root_strap(BaseKind.debian, "arm64", dockerfiles.DEBIAN_APT)
    argv = strap.argv("/tmp/x/root.tar", "http://deb.debian.org/debian")
    hooks = [arg for arg in argv if arg.startswith("--") and "-hook=" in arg]
    # py3compile is diverted away before the python3 packages are set up, and back before the one compile
    assert hooks[0].startswith("--essential-hook=") and "--add /usr/bin/py3compile" in hooks[0]
    assert hooks[1].startswith("--customize-hook=") and "--remove /usr/bin/py3compile" in hooks[1]
    assert hooks[2].startswith("--customize-hook=") and "compileall" in hooks[2]
    assert all(folder in hooks[2] for folder in arches.PYTHON_MODULE_DIRS)
    # the hooks are part of the root's content hash: a root made without them is made again
    assert strap.key() != arches.RootStrap(strap.arch, strap.packages, hooks=()).key()


def _elf(machine: int, *, big: bool = False) -> bytes:
    order = ">" if big else "<"
    return b"\x7fELF" + bytes([2, 2 if big else 1, 1]) + bytes(9) + struct.pack(f"{order}HH", 2, machine)


def test_elf_arch_reads_the_machine_field() -> None:
    assert arches.elf_arch(_elf(183)) == "arm64"
    assert arches.elf_arch(_elf(62)) == "amd64"
    assert arches.elf_arch(_elf(40)) == "machine-40"
    assert arches.elf_arch(_elf(183, big=True)) == "arm64"
    assert arches.elf_arch(b"#!/usr/bin/env python3\n" + bytes(20)) is None
    assert arches.elf_arch(b"\x7fELF") is None
