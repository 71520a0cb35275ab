"""prepare-base's order of work: every arch's root at once, each arch's base as soon as its root is there."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from robocore.commands import prepare_base
from robocore.commands.support import machine
from robocore.commands.support.context import Options
from robocore.commands.support.reporting import Outcome
from robocore.errors import DockerError, ToolMissing

ROOT_WAIT = 10.0  # seconds the emulated root waits for the native base before it gives up


@dataclass
class Steps:
    """A root and a base step for amd64 (native) and arm64 (emulated) that record what they did, in order."""

    failing_root: str | None = None
    events: list[str] = field(default_factory=list)
    native_base_built: threading.Event = field(default_factory=threading.Event)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def log(self, text: str) -> None:
        with self.lock:
            self.events.append(text)

    def make_root(self, arch: str) -> None:
        self.log(f"root {arch} started")
        if arch == "arm64":  # the emulated bootstrap: still running when the native base is built
            self.log(f"root arm64 saw the amd64 base: {self.native_base_built.wait(ROOT_WAIT)}")
        if arch == self.failing_root:
            raise DockerError(f"no root for {arch}")
        self.log(f"root {arch} done")

    def build_base(self, arch: str) -> list[Outcome]:
        self.log(f"base {arch} built")
        if arch == "amd64":
            self.native_base_built.set()
        return [Outcome(what=f"base:{arch}", role="base", action="built")]


def test_the_native_base_is_built_while_the_emulated_root_is_made() -> None:
    steps = Steps()
    outcomes = prepare_base.bases_as_roots_arrive(["amd64", "arm64"], steps.make_root, steps.build_base)
    assert "root arm64 saw the amd64 base: True" in steps.events  # one after the other, it would have waited
    assert steps.events.index("base amd64 built") < steps.events.index("root arm64 done")
    assert steps.events.index("root arm64 done") < steps.events.index("base arm64 built")
    assert [o.what for o in outcomes] == ["base:amd64", "base:arm64"]


def test_a_root_that_cannot_be_had_fails_the_command_after_the_other_arch_is_built() -> None:
    steps = Steps(failing_root="arm64")
    with pytest.raises(DockerError, match="no root for arm64"):
        prepare_base.bases_as_roots_arrive(["amd64", "arm64"], steps.make_root, steps.build_base)
    assert "base amd64 built" in steps.events
    assert "base arm64 built" not in steps.events


MIXED = """\
ros_distro: jazzy
base: {kind: official}
hosts:
  - {name: ipc, ip: 10.0.0.1}
  - {name: pi, ip: 10.0.0.2, arch: arm64}
components:
  - {name: talker, folder: components/talker, runs_on: ipc}
  - {name: listener, folder: components/listener, runs_on: pi}
"""


def test_emulation_is_checked_before_any_root_or_docker(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """No qemu registered for arm64: prepare-base stops with that, before it asks Docker for anything (the daemon
    here cannot be reached: had it been asked first, the error would be Docker's)."""
    for folder in ("components/talker", "components/listener"):
        (tmp_path / folder).mkdir(parents=True)
    (tmp_path / "robot.yaml").write_text(MIXED)
    (tmp_path / "binfmt_misc").mkdir()
    monkeypatch.setattr(machine, "BINFMT_DIR", tmp_path / "binfmt_misc")
    monkeypatch.setenv("DOCKER_HOST", f"unix://{tmp_path}/no-docker.sock")
    with pytest.raises(ToolMissing, match=r"robot\.yaml: hosts of arch"):  # the arch this machine does not run
        prepare_base.prepare_base(Options(project_dir=tmp_path, task="prepare-base"), force=False)
