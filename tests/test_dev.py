"""robocore dev: deploy, then again on each save; quick saves coalesce; a failed build deploys nothing and says
why in one line; the loop goes on watching."""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from robocore.commands import build, dev, run, sync
from robocore.commands.support.context import Options
from robocore.errors import BuildError


class Robot:
    """The deploy steps, faked: what each saw of the watched file, and which steps ran."""

    def __init__(self, source: Path, fail_builds: set[int] | None = None) -> None:
        self.source = source
        self.steps: list[str] = []
        self.built: list[str] = []
        self.fail_builds = fail_builds or set()
        self.said: list[str] = []

    def install(self, monkeypatch: pytest.MonkeyPatch, paths: list[Path]) -> None:
        def fake_build(options: Options, *, component: str | None, full: bool = False) -> None:
            self.built.append(self.source.read_text())
            self.steps.append("build")
            if len(self.built) in self.fail_builds:
                raise BuildError("colcon build failed for demo_talker (log: .robocore/build/talker/log)\n"
                                 "  File setup.py, line 3\n  SyntaxError")  # a log tail, as colcon's errors have

        monkeypatch.setattr(build, "build", fake_build)
        monkeypatch.setattr(sync, "sync", lambda options, *, host: self.steps.append("sync"))
        monkeypatch.setattr(run, "run", lambda options, *, host, tag: self.steps.append("run"))
        monkeypatch.setattr(dev, "watched", lambda options, component: paths)


def start(tmp_path: Path, rounds: int, settle: float) -> threading.Thread:
    def loop() -> None:
        dev.dev(Options(project_dir=tmp_path, quiet=True), component=None, rounds=rounds, poll=0.02,
                  settle=settle, say=said.append)

    said: list[str] = []
    thread = threading.Thread(target=loop, daemon=True)
    thread.said = said  # type: ignore[attr-defined]
    thread.start()
    return thread


def save(path: Path, text: str) -> None:
    """Save ``path`` as editors do, atomically: the new text goes to a file beside the watched folder, then is renamed
    over ``path``. A write in place (truncate, then write) could be seen half-done: a writer descheduled between the
    two for longer than the settle time leaves the loop an empty file that has stopped changing, so it deploys that."""
    staged = path.parent.parent / f".{path.name}.saving"
    staged.write_text(text)
    os.replace(staged, path)


def wait_for(condition: Any, what: str, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f"timed out waiting for {what}")
        time.sleep(0.01)


def test_quick_saves_coalesce_into_one_deploy_of_the_last_one(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    source = tmp_path / "ws" / "talker.py"
    source.parent.mkdir()
    source.write_text("v0")
    robot = Robot(source)
    robot.install(monkeypatch, [tmp_path / "ws"])
    thread = start(tmp_path, rounds=1, settle=1.0)
    wait_for(lambda: robot.steps == ["build", "sync", "run"], "the first deploy")
    time.sleep(0.1)
    for n in range(1, 6):  # five saves, far quicker than the settle time
        source.write_text(f"v{n}")
        time.sleep(0.01)
    thread.join(timeout=60)
    assert not thread.is_alive()
    assert robot.built == ["v0", "v5"]  # no deploy of a half-saved state
    assert robot.steps == ["build", "sync", "run"] * 2


def test_a_failed_build_deploys_nothing_says_why_and_the_loop_goes_on(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    source = tmp_path / "ws" / "talker.py"
    source.parent.mkdir()
    source.write_text("good")
    robot = Robot(source, fail_builds={2})
    robot.install(monkeypatch, [tmp_path / "ws"])
    thread = start(tmp_path, rounds=2, settle=0.05)
    wait_for(lambda: len(robot.steps) == 3, "the first deploy")
    save(source, "broken")
    wait_for(lambda: len(robot.built) == 2, "the failing build")
    wait_for(lambda: any(line.startswith("dev: build failed") for line in thread.said), "the failure line")  # type: ignore[attr-defined]
    save(source, "fixed")
    thread.join(timeout=60)
    assert not thread.is_alive()
    assert robot.steps == ["build", "sync", "run", "build", "build", "sync", "run"]  # nothing after the failed build
    [line] = [s for s in thread.said if s.startswith("dev: build failed")]  # type: ignore[attr-defined]
    assert line == ("dev: build failed: colcon build failed for demo_talker (log: .robocore/build/talker/log) "
                    "(the robot keeps running the last good release; watching for the next save)")
    assert robot.built == ["good", "broken", "fixed"]


def test_a_dry_run_plans_one_deploy_and_watches_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[tuple[str, bool]] = []
    monkeypatch.setattr(build, "build",
                        lambda options, *, component, full=False: seen.append(("build", options.dry_run)))
    monkeypatch.setattr(sync, "sync", lambda options, *, host: seen.append(("sync", options.dry_run)))
    monkeypatch.setattr(run, "run", lambda options, *, host, tag: seen.append(("run", options.dry_run)))
    monkeypatch.setattr(dev, "watched", lambda options, component: pytest.fail("a dry run watched"))
    dev.dev(Options(project_dir=tmp_path, dry_run=True), component="talker", say=lambda line: None)
    assert seen == [("build", True), ("sync", True), ("run", True)]


def test_a_small_workspace_is_looked_at_every_poll() -> None:
    assert dev.poll_pause(0.0005) == dev.POLL
    assert dev.poll_pause(0.0005, 0.02) == 0.02


def test_a_costly_look_waits_in_proportion_so_watching_stays_a_fraction_of_a_core() -> None:
    look = 0.02
    pause = dev.poll_pause(look)
    assert pause == look * dev.POLL_COST_RATIO
    assert look / (look + pause) <= 0.1


def test_the_pause_has_a_ceiling() -> None:
    assert dev.poll_pause(10.0) == dev.POLL_MAX
    assert dev.poll_pause(10.0, 2.0) == 2.0  # a longer least pause asked for is kept


def linked_project(tmp_path: Path) -> tuple[Path, Path, Path]:
    """A project whose component folder holds links outside it (a folder, a file) and one inside it (a folder)."""
    project, outside = tmp_path / "robot", tmp_path / "elsewhere"
    (outside / "tree").mkdir(parents=True)
    (outside / "tree" / "big.txt").write_text("outside")
    (outside / "notes.txt").write_text("outside")
    ws = project / "ws"
    (project / "shared").mkdir(parents=True)
    (project / "shared" / "lib.py").write_text("inside")
    ws.mkdir()
    (ws / "talker.py").write_text("v0")
    (ws / "ext").symlink_to(outside / "tree", target_is_directory=True)  # a `cfg -> /root` a clone may carry
    (ws / "notes").symlink_to(outside / "notes.txt")
    (ws / "relative").symlink_to("../../elsewhere/tree", target_is_directory=True)
    (ws / "shared").symlink_to("../shared", target_is_directory=True)  # inside: followed
    return project, ws, outside


def test_the_watch_never_reads_or_watches_outside_the_project_through_a_link(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import os

    from robocore.commands.support import noop

    project, ws, outside = linked_project(tmp_path)
    looked: list[str] = []  # every path the look stats, lists or opens
    for name in ("stat", "lstat", "scandir", "open", "listdir"):
        real = getattr(os, name)

        def spy(path: Any, *args: Any, _real: Any = real, **kwargs: Any) -> Any:
            looked.append(os.fspath(path))
            return _real(path, *args, **kwargs)

        monkeypatch.setattr(os, name, spy)
    before = noop.folders_digest([project / "robot.yaml", ws], project)
    monkeypatch.undo()
    assert looked
    links = [str(ws / name) for name in ("ext", "notes", "relative")]
    through = [p for p in looked if p.startswith(str(outside)) or any(p.startswith(link + "/") for link in links)]
    assert through == []
    # a change outside is not seen; the same change inside, through the inside link, is (the negative control)
    (outside / "tree" / "big.txt").write_text("changed outside")
    (outside / "tree" / "new.txt").write_text("added outside")
    (outside / "notes.txt").write_text("changed outside too")
    assert noop.folders_digest([project / "robot.yaml", ws], project) == before
    (project / "shared" / "lib.py").write_text("changed inside")
    assert noop.folders_digest([project / "robot.yaml", ws], project) != before


def test_a_retargeted_link_and_a_linked_component_folder_count_by_the_link_itself(tmp_path: Path) -> None:
    from robocore.commands.support import noop

    project, ws, outside = linked_project(tmp_path)
    linked_ws = project / "linked-ws"
    linked_ws.symlink_to(outside / "tree", target_is_directory=True)
    before = noop.folders_digest([ws, linked_ws], project)
    (outside / "tree" / "big.txt").write_text("changed outside")
    assert noop.folders_digest([ws, linked_ws], project) == before  # nothing behind the linked folder is watched
    (ws / "ext").unlink()
    (ws / "ext").symlink_to(outside, target_is_directory=True)
    retargeted = noop.folders_digest([ws, linked_ws], project)
    assert retargeted != before
    linked_ws.unlink()
    linked_ws.symlink_to(outside, target_is_directory=True)
    assert noop.folders_digest([ws, linked_ws], project) != retargeted
