"""prepare-base's order of work: every arch's root at once, each arch's base as soon as its root is there."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import pytest

from robocore.commands import base_image
from robocore.errors import DockerError

ROOT_WAIT = 10.0  # seconds the emulated root waits for the native base before it gives up


@dataclass
class Run:
    """What the fakes saw, in order."""

    events: list[str] = field(default_factory=list)
    native_base_built: threading.Event = field(default_factory=threading.Event)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def log(self, text: str) -> None:
        with self.lock:
            self.events.append(text)


def _fakes(monkeypatch: pytest.MonkeyPatch, run: Run, *, failing_root: str | None = None) -> Any:
    monkeypatch.setattr(base_image, "arches", lambda project: ["amd64", "arm64"])
    monkeypatch.setattr(base_image, "native_arch", lambda: "amd64")
    monkeypatch.setattr(base_image, "check_emulation", lambda arch, native, where: run.log(f"checked {arch}"))
    monkeypatch.setattr(base_image, "local_docker", lambda: SimpleNamespace(close=lambda: None))

    def make_root(project: object, arch: str, say: object) -> None:
        run.log(f"root {arch} started")
        if arch == "arm64":  # the emulated bootstrap: still running when the native base is built
            run.log(f"root arm64 saw the amd64 base: {run.native_base_built.wait(ROOT_WAIT)}")
        if arch == failing_root:
            raise DockerError(f"no root for {arch}")
        run.log(f"root {arch} done")

    def plan_base(project: object, client: object, arch: str, **kwargs: object) -> Any:
        return SimpleNamespace(arch=arch, plan=SimpleNamespace(ref=f"base:{arch}", role="base"))

    def triage(planned: Any, reason: object, dry_run: bool, outcomes: list[Any], work: list[Any]) -> None:
        work.append((planned, "new"))

    def run_builds(report: object, work: list[Any], *, parallel: bool) -> list[Any]:
        for planned, _ in work:
            run.log(f"base {planned.arch} built")
            if planned.arch == "amd64":
                run.native_base_built.set()
        return []

    monkeypatch.setattr(base_image, "_make_root", make_root)
    monkeypatch.setattr(base_image, "plan_base", plan_base)
    monkeypatch.setattr(base_image, "triage", triage)
    monkeypatch.setattr(base_image, "run_builds", run_builds)
    monkeypatch.setattr(base_image, "decide", lambda state, planned, force: "new")
    monkeypatch.setattr(base_image, "report_outcomes", lambda report, outcomes: None)
    monkeypatch.setattr(base_image.dockerfiles, "refuse_robot_shape", lambda project: None)
    monkeypatch.setattr("robocore.adapters.image_builder.image_state", lambda client, ref: None)
    report = SimpleNamespace(info=lambda text: None)
    return SimpleNamespace(load=lambda: object(), report=report, dry_run=False)


def test_the_native_base_is_built_while_the_emulated_root_is_made(monkeypatch: pytest.MonkeyPatch) -> None:
    run = Run()
    base_image.prepare_base(_fakes(monkeypatch, run), force=False)
    assert run.events[:2] == ["checked amd64", "checked arm64"]  # emulation is checked before any bootstrap
    assert "root arm64 saw the amd64 base: True" in run.events  # one after the other, it would have waited
    assert run.events.index("base amd64 built") < run.events.index("root arm64 done")
    assert run.events.index("root arm64 done") < run.events.index("base arm64 built")
    assert run.events.count("base amd64 built") == run.events.count("base arm64 built") == 1


def test_a_root_that_cannot_be_had_fails_the_command_after_the_other_arch_is_built(
        monkeypatch: pytest.MonkeyPatch) -> None:
    run = Run()
    with pytest.raises(DockerError, match="no root for arm64"):
        base_image.prepare_base(_fakes(monkeypatch, run, failing_root="arm64"), force=False)
    assert "base amd64 built" in run.events
    assert "base arm64 built" not in run.events
