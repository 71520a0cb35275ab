"""Refusals about arches (robocore.commands.support.arch_checks): install trees of another arch, daemons that cannot run
their host's arch; and the build's per-arch records (ccache folder, install marker, clean build on an arch change)."""

from __future__ import annotations

import dataclasses
import struct
from pathlib import Path

import pytest

from robocore.commands import build
from robocore.commands.support import arch_checks, images, machine
from robocore.config.model import Host
from robocore.errors import ArchMismatch
from robocore.plan import arches, containers, dockerfiles, naming
from robocore.project import Project


def _elf(machine: int) -> bytes:
    return b"\x7fELF" + bytes([2, 1, 1]) + bytes(9) + struct.pack("<HH", 2, machine) + bytes(40)


def _tree(tmp_path: Path, *, marker: str | None, elves: dict[str, int]) -> Path:
    install = tmp_path / "install"
    (install / "lib" / "pkg").mkdir(parents=True)
    (install / "setup.bash").write_text("# not an ELF\n")
    if marker is not None:
        (install / arches.INSTALL_ARCH_FILE).write_text(marker + "\n")
    for name, code in elves.items():
        (install / "lib" / "pkg" / name).write_bytes(_elf(code))
    return install


def _host(arch: str, name: str = "jetson") -> Host:
    return Host.model_validate({"name": name, "ip": "10.0.0.2", "arch": arch})


def test_a_tree_of_the_hosts_arch_passes(tmp_path: Path) -> None:
    install = _tree(tmp_path, marker="arm64", elves={"talker": 183})
    arch_checks.refuse_foreign_install(install, _host("arm64"), "talker")
    assert arch_checks.install_tree_arch(install) == ("arm64", None)


def test_a_tree_built_for_another_arch_is_refused_in_one_line(tmp_path: Path) -> None:
    install = _tree(tmp_path, marker="amd64", elves={"talker": 62})
    with pytest.raises(ArchMismatch) as info:
        arch_checks.refuse_foreign_install(install, _host("arm64"), "talker")
    message = info.value.message
    assert "\n" not in message and "was built for amd64, but host jetson is arm64" in message
    assert info.value.exit_code == 2 and "build --component talker" in (info.value.hint or "")


def test_an_elf_of_another_arch_in_a_marked_tree_is_refused(tmp_path: Path) -> None:
    install = _tree(tmp_path, marker="arm64", elves={"a_good": 183, "talker": 62})
    with pytest.raises(ArchMismatch, match=r"mixes arches \(arm64 and lib/pkg/talker \(amd64\)\)"):
        arch_checks.refuse_foreign_install(install, _host("arm64"), "talker")


def test_an_unmarked_tree_is_judged_by_its_elf_headers(tmp_path: Path) -> None:
    install = _tree(tmp_path, marker=None, elves={"talker": 62})
    with pytest.raises(ArchMismatch, match="was built for amd64"):
        arch_checks.refuse_foreign_install(install, _host("arm64"), "talker")
    python_only = _tree(tmp_path / "py", marker=None, elves={})
    arch_checks.refuse_foreign_install(python_only, _host("arm64"), "listener")


def test_a_symlinked_elf_is_not_followed(tmp_path: Path) -> None:
    install = _tree(tmp_path, marker="arm64", elves={})
    outside = tmp_path / "x86"
    outside.write_bytes(_elf(62))
    link = install / "lib" / "pkg" / "link"
    link.symlink_to(outside)
    arch_checks.refuse_foreign_install(install, _host("arm64"), "talker")
    link.unlink()
    link.write_bytes(outside.read_bytes())  # the same ELF in the tree itself is refused
    with pytest.raises(ArchMismatch, match=r"lib/pkg/link \(amd64\)"):
        arch_checks.refuse_foreign_install(install, _host("arm64"), "talker")


def _binfmt(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, text: str | None) -> None:
    folder = tmp_path / "binfmt_misc"
    folder.mkdir()
    if text is not None:
        (folder / "qemu-aarch64").write_text(text)
    monkeypatch.setattr(machine, "BINFMT_DIR", folder)


def test_native_and_emulated_hosts(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _binfmt(tmp_path, monkeypatch, "enabled\ninterpreter /usr/libexec/qemu-binfmt/aarch64-binfmt-P\nflags: POF\n")
    local = Host.model_validate({"name": "dev", "ip": "127.0.0.1", "arch": "arm64"})
    assert arch_checks.host_arch(local, "aarch64").describe() == "arm64 native"
    emulated = arch_checks.refuse_daemon_arch(local, "x86_64")
    assert emulated.emulated and emulated.describe() == "arm64 emulated (qemu-aarch64 on amd64)"


@pytest.mark.parametrize(("text", "why"), [
    (None, "is not registered"),
    ("disabled\nflags: POF\n", "is disabled"),
    ("enabled\nflags: PO\n", "lacks the F flag (flags: PO)"),
])
def test_a_daemon_that_cannot_run_the_hosts_arch_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                            text: str | None, why: str) -> None:
    _binfmt(tmp_path, monkeypatch, text)
    local = Host.model_validate({"name": "dev", "ip": "127.0.0.1", "arch": "arm64"})
    found = arch_checks.host_arch(local, "x86_64")
    assert found.describe() == "arm64 (cannot run on amd64)"
    with pytest.raises(ArchMismatch) as info:
        arch_checks.refuse_daemon_arch(local, "x86_64")
    assert "\n" not in info.value.message and why in info.value.message
    assert "its Docker daemon runs on amd64 and cannot run arm64 images" in info.value.message
    assert "qemu-user-static" in (info.value.hint or "")


ROBOT = """\
ros_distro: noetic
base: {{kind: debian}}
hosts:
  - {{name: ipc, ip: 192.168.1.10, arch: amd64}}
  - {{name: jetson, ip: 192.168.1.20, arch: arm64}}
discovery: {{servers: [{{host: {master}}}]}}
components:
  - {{name: talker, folder: components/talker, runs_on: {talker}}}
"""
PACKAGE = """<?xml version="1.0"?>
<package format="3"><name>demo_talker</name><version>0.1.0</version><description>d</description>
<maintainer email="me@example.com">me</maintainer><license>MIT</license>
<buildtool_depend>catkin</buildtool_depend></package>
"""


def _project(tmp_path: Path, *, talker: str = "jetson", master: str = "ipc") -> Project:
    (tmp_path / "robot.yaml").write_text(ROBOT.format(talker=talker, master=master))
    pkg = tmp_path / "components" / "talker" / "src" / "demo_talker"
    pkg.mkdir(parents=True, exist_ok=True)
    (pkg / "package.xml").write_text(PACKAGE)
    (pkg / "CMakeLists.txt").write_text("project(demo_talker)\n")
    return Project.load(tmp_path)


def test_a_build_for_another_arch_than_the_last_one_starts_clean(tmp_path: Path) -> None:
    project = _project(tmp_path)
    plan = build.plan_build(project, project.component("talker"), "img")
    assert plan.arch == "arm64" and plan.changed is None and not plan.clean
    (plan.out / "install").mkdir(parents=True)
    build.write_atomic(plan.out / "install" / arches.INSTALL_ARCH_FILE, "arm64\n")
    build.record_build(plan)
    again = build.plan_build(project, project.component("talker"), "img")
    assert again.changed == [] and not again.clean
    moved = _project(tmp_path, talker="ipc")  # the talker now runs on the amd64 host
    redo = build.plan_build(moved, moved.component("talker"), "img")
    assert redo.clean and redo.changed is None and redo.reason == "arch changed (arm64 -> amd64): clean build"
    with_cache = build.with_cmake_toolchain(moved, redo, {"dev.robocore.toolchain": "cmake"})
    assert with_cache.ccache == moved.state_dir / "ccache" / "amd64"


@pytest.mark.parametrize("native", ["amd64", "arm64"])
@pytest.mark.parametrize("master", ["ipc", "jetson"])
def test_the_master_runs_the_base_of_its_hosts_arch(tmp_path: Path, native: str, master: str) -> None:
    """Wherever the master is, and whatever this machine's arch, the image steps accept the robot and the master
    runs the base prepare-base makes for its host's arch (``latest`` when that is this machine's)."""
    project = dataclasses.replace(_project(tmp_path, master=master), native_arch=native)
    dockerfiles.refuse_robot_shape(project)
    arch = {"ipc": "amd64", "jetson": "arm64"}[master]
    assert images.base_arches(project) == sorted({"arm64", arch})  # the talker's and the master's
    [spec] = [s for s in containers.host_specs(project, master) if s.role == naming.ROLE_DISCOVERY]
    assert spec.image == f"{project.name}-base:{arches.base_tag(arch, native)}"
    assert spec.image.endswith(":latest") == (arch == native)
    [released] = [s for s in containers.host_specs(project, master, tag="v1") if s.role == naming.ROLE_DISCOVERY]
    assert released.image == f"{project.name}-base:v1"  # one multi-arch name: the host pulls its own arch


def test_a_robot_with_no_host_of_this_machines_arch_has_only_that_arch(tmp_path: Path) -> None:
    """One arm64 host, seen from an amd64 machine: one base (arm64), which the master runs, and no amd64 image."""
    (tmp_path / "robot.yaml").write_text(ALL_ARM64)
    (tmp_path / "components" / "talker").mkdir(parents=True)
    project = dataclasses.replace(Project.load(tmp_path), native_arch="amd64")
    dockerfiles.refuse_robot_shape(project)
    assert images.base_arches(project) == ["arm64"]
    specs = containers.host_specs(project, "pi")
    assert [(s.role, s.image) for s in specs] == [
        (naming.ROLE_DISCOVERY, f"{project.name}-base:latest-arm64"),
        (naming.ROLE_COMPONENT, f"{project.name}-talker:latest")]


ALL_ARM64 = """ros_distro: noetic
base: {kind: debian}
hosts:
  - {name: pi, ip: 192.168.1.20, arch: arm64}
components:
  - {name: talker, folder: components/talker, runs_on: pi}
"""


def test_a_step_on_an_emulated_daemon_may_take_longer() -> None:
    """A discovery server gets the native 20 s on a daemon of its arch, five times that under qemu."""
    from robocore.commands.run import SERVER_READY_TIMEOUT

    assert arch_checks.allowing_emulation(SERVER_READY_TIMEOUT, emulated=False) == 20.0
    assert arch_checks.allowing_emulation(SERVER_READY_TIMEOUT, emulated=True) == 100.0
