"""Refusals about CPU arches, one line each, before anything is copied or started: an install tree built for
another arch than its host's, and a host whose Docker daemon cannot run its arch (no qemu registration).

The arch an install tree was built for is read from what ``build`` recorded in it
(:data:`robocore.plan.arches.INSTALL_ARCH_FILE`) and checked against the ELF headers of its files, so a tree
swapped or patched by hand is caught too.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from robocore.commands.support import machine as dev_machine
from robocore.commands.support.machine import binfmt_problem, emulation_hint
from robocore.config.model import Host, docker_arch, kernel_arch
from robocore.errors import ArchMismatch, RobocoreError
from robocore.plan import arches

#: ELF files read at most per install tree (their first 20 bytes each).
MAX_ELF_SCAN = 20000


def install_tree_arch(install: Path) -> tuple[str | None, str | None]:
    """(the arch the tree records, the first file whose ELF header says another arch: ``path (arch)``)."""
    try:
        recorded = (install / arches.INSTALL_ARCH_FILE).read_text().strip() or None
    except OSError:
        recorded = None
    seen = 0
    for dirpath, dirnames, filenames in os.walk(install):
        dirnames.sort()
        for name in sorted(filenames):
            path = Path(dirpath) / name
            if path.is_symlink():
                continue
            try:
                with path.open("rb") as handle:
                    found = arches.elf_arch(handle.read(20))
            except OSError:
                continue
            if found is None:
                continue
            seen += 1
            if recorded is None:
                recorded = found
            if found != recorded:
                return recorded, f"{path.relative_to(install)} ({found})"
            if seen >= MAX_ELF_SCAN:
                return recorded, None
    return recorded, None


def refuse_foreign_install(install: Path, host: Host, component: str) -> None:
    """ArchMismatch (one line) when the install tree of ``component`` holds binaries of another arch than ``host``."""
    want = host.arch.value
    recorded, odd = install_tree_arch(install)
    if odd is not None:
        raise ArchMismatch(f"component {component}: its install tree {install} mixes arches ({recorded} and "
                           f"{odd}); refusing to sync it to host {host.name} ({want})",
                           hint=f"run `build --component {component}` to rebuild it for {want}")
    if recorded is not None and recorded != want:
        raise ArchMismatch(f"component {component}: its install tree {install} was built for {recorded}, but host "
                           f"{host.name} is {want}; refusing to sync it",
                           hint=f"run `build --component {component}` (it builds for the host's arch)")


@dataclass(frozen=True)
class HostArch:
    """How a host's daemon runs the arch robot.yaml gives the host."""

    arch: str  # robot.yaml's
    machine: str  # the daemon's (``docker info`` Architecture, as Docker names it)
    emulated: bool
    problem: str | None = None  # the one-line refusal, when it cannot run it
    hint: str | None = None

    def describe(self) -> str:
        """``arm64 native`` / ``arm64 emulated (qemu-aarch64 on amd64)`` / ``arm64 (cannot run on amd64)``."""
        if self.problem:
            return f"{self.arch} (cannot run on {self.machine})"
        if self.emulated:
            return f"{self.arch} emulated (qemu-{kernel_arch(self.arch)} on {self.machine})"
        return f"{self.arch} native"


def binfmt_entry_text(host: Host, arch: str) -> str | None:
    """The text of the host's binfmt_misc entry ``qemu-<machine>`` (read over ssh for a remote host); None when
    there is none or it cannot be read."""
    entry = dev_machine.BINFMT_DIR / f"qemu-{kernel_arch(arch)}"
    if host.is_local:
        try:
            return entry.read_text()
        except OSError:
            return None
    from robocore.adapters import ssh

    try:
        done = ssh.run(host, ["cat", "--", str(entry)], timeout=20, check=False)
    except RobocoreError:
        return None
    return done.stdout.decode(errors="replace") if done.returncode == 0 else None


def host_arch(host: Host, daemon_machine: str) -> HostArch:
    """Whether ``host``'s daemon (``daemon_machine``, from ``docker info``) runs ``host.arch``: natively, emulated
    through a qemu binfmt_misc entry with the F flag (so it works inside containers), or not at all."""
    want, machine = host.arch.value, docker_arch(daemon_machine)
    if machine == want:
        return HostArch(want, machine, emulated=False)
    qemu = f"qemu-{kernel_arch(want)}"
    why = binfmt_problem(binfmt_entry_text(host, want))
    if why is None:
        return HostArch(want, machine, emulated=True)
    return HostArch(
        want, machine, emulated=False,
        problem=f"host {host.name}: robot.yaml says arch: {want} but its Docker daemon runs on {machine} and "
                f"cannot run {want} images ({dev_machine.BINFMT_DIR}/{qemu} {why})",
        hint=f"on {host.name} {emulation_hint(want)}; or set arch: {machine} for host {host.name}",
    )


def refuse_daemon_arch(host: Host, daemon_machine: str) -> HostArch:
    """:func:`host_arch`, raising its problem as ArchMismatch."""
    found = host_arch(host, daemon_machine)
    if found.problem:
        raise ArchMismatch(found.problem, hint=found.hint)
    return found


#: How much longer a step may take on a daemon that runs its host's arch through qemu: emulated Python runs 4-5
#: times slower than native (a ROS master is Python: an arm64 one under qemu on a busy 2-core machine took more
#: than the native 20 s to serve).
EMULATED_SLOWDOWN = 5


def allowing_emulation(seconds: float, *, emulated: bool) -> float:
    """``seconds`` (what a step may take natively), stretched when the daemon runs the arch ``emulated``."""
    return seconds * (EMULATED_SLOWDOWN if emulated else 1)
