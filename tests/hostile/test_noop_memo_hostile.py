"""The no-op memo as a way in: ``.robocore/noop`` and every file in it are read like the other state
folders (never through a link, regular files only, size-capped, never a FIFO or device), a memo that cannot be
trusted is dropped (a test for each way of faking one), the snapshot's walk never leaves the project through a
link, and a file written twice within one clock tick is still seen (git's "racily clean" entries).
"""

from __future__ import annotations

import io
import json
import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from robocore.commands.support import noop, status_memo, trees
from robocore.files import is_private

GOOD = ("ros_distro: jazzy\nhosts:\n  - name: dev\n    ip: 127.0.0.1\n    docker: local\n"
        "components:\n  - name: talker\n    runs_on: dev\n    image: vendor/talker:1\n")


def project(tmp_path: Path, name: str = "robot") -> Path:
    root = tmp_path / name
    (root / "src").mkdir(parents=True)
    (root / "src" / "node.py").write_text("print('hello')\n")
    (root / "robot.yaml").write_text(GOOD)
    return root


def recorded(root: Path, text: str = "ok\n") -> noop.Memo:
    """The ordinary path of a no-op run, then its memo written."""
    run = noop.Memo(root, "validate", [])
    assert not run.replay(io.StringIO(), io.StringIO())
    assert run.record(text, "")
    return run


def replays(root: Path) -> tuple[bool, str]:
    out = io.StringIO()
    return noop.Memo(root, "validate", []).replay(out, io.StringIO()), out.getvalue()


def robocore(root: Path, *args: str, **env: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "robocore", *args], cwd=root, capture_output=True, text=True,
                          timeout=120, stdin=subprocess.DEVNULL,
                          env={**os.environ, "DOCKER_HOST": f"unix://{root}/nobody.sock", **env})


# ------------------------------------------------------------------------------ the walk stays in the project


def test_a_link_to_a_folder_outside_stops_the_walk_at_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``cfg -> a big tree`` outside: not one folder of the tree is listed; no memo is read or written."""
    root = project(tmp_path)
    big = tmp_path / "big"
    for index in range(50):
        (big / f"d{index}").mkdir(parents=True)
    (root / "cfg").symlink_to(big, target_is_directory=True)
    listed: list[str] = []
    real_scandir = os.scandir

    def scandir(path: str) -> object:
        listed.append(str(path))
        return real_scandir(path)

    monkeypatch.setattr(noop.os, "scandir", scandir)
    run = noop.Memo(root, "validate", [])
    assert run.take() is None
    assert not any(path.startswith(str(big)) for path in listed)
    assert not run.replay(io.StringIO(), io.StringIO()) and not run.record("ok\n", "")
    assert not run.path.exists()


def test_links_inside_the_project_are_followed_and_a_loop_is_walked_once(tmp_path: Path) -> None:
    root = project(tmp_path)
    (root / "src" / "again").symlink_to("..", target_is_directory=True)  # a loop back to the project
    (root / "alias").symlink_to("src", target_is_directory=True)
    recorded(root)
    assert replays(root) == (True, "ok\n")
    (root / "src" / "node.py").write_text("print('changed')\n")
    assert replays(root)[0] is False


def test_a_link_to_a_file_outside_is_listed_not_opened(tmp_path: Path) -> None:
    """A link to ``/dev/zero`` or a FIFO outside: its target's stat is in the snapshot, nothing is read."""
    root = project(tmp_path)
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    (root / "zero").symlink_to("/dev/zero")
    (root / "pipe").symlink_to(fifo)
    recorded(root)
    assert replays(root) == (True, "ok\n")


def test_validate_through_the_command_with_a_link_to_usr(tmp_path: Path) -> None:
    """The reproduction: ``extlink -> /usr``; validate answers by its ordinary path, writes no memo."""
    root = project(tmp_path)
    (root / "extlink").symlink_to("/usr", target_is_directory=True)
    done = robocore(root, "validate")
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    assert not (root / ".robocore" / "noop").exists()


# ------------------------------------------------------------------------------ the memo folder and files


def test_a_linked_memo_folder_is_harmless_to_validate_and_refused_by_a_writing_task(tmp_path: Path) -> None:
    """The reproduction: validate printed ok, then an ``UnsafePath`` traceback. Now validate (which writes only
    the memo) answers with no memo, and a task that writes state refuses the link in one line."""
    root = project(tmp_path)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (root / ".robocore").mkdir()
    (root / ".robocore" / "noop").symlink_to(elsewhere, target_is_directory=True)
    for _ in range(2):
        done = robocore(root, "validate")
        assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    refused = robocore(root, "stage", "--refresh")
    assert refused.returncode != 0 and "Traceback" not in refused.stderr
    lines = [line for line in refused.stderr.splitlines() if not line.startswith("hint:")]
    assert len(lines) == 1 and ".robocore/noop" in lines[0] and "symlink" in lines[0], refused.stderr
    assert list(elsewhere.iterdir()) == [] and (root / ".robocore" / "noop").is_symlink()


def plant(root: Path, kind: str, tmp_path: Path) -> Path:
    """Something at the memo's name that robocore did not write."""
    run = noop.Memo(root, "validate", [], line=[str(root), "validate"])
    path = run.path
    path.parent.mkdir(parents=True, exist_ok=True)
    os.chmod(path.parent, 0o700)
    os.chmod(path.parent.parent, 0o700)
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "device":
        path.symlink_to("/dev/zero")
    elif kind == "link":
        target = tmp_path / "forged.json"
        target.write_text(noop.seal({"snapshot": "x", "young": {}, "stdout": "forged\n"}))
        path.symlink_to(target)
    elif kind == "oversized":
        with open(path, "wb") as handle:
            handle.truncate(noop.MAX_MEMO_BYTES + 1)
    elif kind == "folder":
        path.mkdir()
    return path


@pytest.mark.parametrize("kind", ["fifo", "device", "link", "oversized"])
def test_a_memo_that_is_not_a_small_regular_file_is_dropped(tmp_path: Path, kind: str) -> None:
    root = project(tmp_path)
    path = plant(root, kind, tmp_path)
    memo = noop.Memo(root, "validate", [], line=[str(root), "validate"])
    assert memo.current() is None
    assert not os.path.lexists(path)  # removed as a name: a link's target is untouched
    assert memo.record("ok\n", "")
    assert stat.S_ISREG(os.lstat(path).st_mode)
    if kind == "link":
        assert "forged" in (tmp_path / "forged.json").read_text()


def test_a_folder_at_the_memos_name_is_left_and_no_memo_is_written(tmp_path: Path) -> None:
    root = project(tmp_path)
    path = plant(root, "folder", tmp_path)
    memo = noop.Memo(root, "validate", [], line=[str(root), "validate"])
    assert memo.current() is None
    assert memo.record("ok\n", "") is False  # never raises: the next run is ordinary again
    assert path.is_dir()


@pytest.mark.parametrize("kind", ["fifo", "device"])
def test_the_command_with_a_fifo_or_dev_zero_memo_answers(tmp_path: Path, kind: str) -> None:
    """The reproductions: a FIFO memo hung validate, a ``/dev/zero`` link ran out of memory."""
    root = project(tmp_path)
    plant(root, kind, tmp_path)
    for _ in range(2):
        done = robocore(root, "validate")
        assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    assert robocore(root, "validate").stdout == done.stdout


def test_the_status_memo_is_read_the_same_way(tmp_path: Path) -> None:
    root = project(tmp_path)
    memo = status_memo.memo_for(["-p", str(root), "status"])
    assert memo is not None
    memo.path.parent.mkdir(parents=True)
    os.mkfifo(memo.path)
    assert status_memo.answer(["-p", str(root), "status"]) is False
    assert not os.path.lexists(memo.path)


# ------------------------------------------------------------------------------ faked memos are dropped


def forge(path: Path, change: str) -> None:
    document = noop.unseal(path.read_bytes())
    assert document is not None
    if change == "edited":  # the output changed, the checksum line kept
        head, _, body = path.read_bytes().partition(b"\n")
        path.write_bytes(head + b"\n" + body.replace(b"ok", b"OK"))
    elif change == "truncated":
        path.write_bytes(path.read_bytes()[:-10])
    elif change == "not-json":
        path.write_text(noop.seal({}).split("\n")[0] + "\n[")
    elif change == "group-writable":
        os.chmod(path, 0o620)
    elif change == "world-writable-folder":
        os.chmod(path.parent, 0o777)


@pytest.mark.parametrize("change", ["edited", "truncated", "not-json", "group-writable", "world-writable-folder"])
def test_a_faked_memo_is_dropped_never_believed(tmp_path: Path, change: str) -> None:
    root = project(tmp_path)
    path = recorded(root).path
    assert replays(root) == (True, "ok\n")
    forge(path, change)
    assert replays(root) == (False, "")
    if change != "world-writable-folder":
        assert not path.exists()  # dropped: the next ordinary run writes a good one
    assert recorded(root).path == path
    assert replays(root) == (True, "ok\n")


def test_a_memo_from_another_project_or_a_clone_is_not_believed(tmp_path: Path) -> None:
    """Copied with its project (a clone carries ``.robocore/noop``): new inodes, another path."""
    root = project(tmp_path)
    recorded(root)
    assert replays(root) == (True, "ok\n")
    clone = tmp_path / "clone"
    shutil.copytree(root, clone, symlinks=True)
    copied = noop.Memo(clone, "validate", [])
    (clone / ".robocore" / "noop" / root.name).mkdir()  # nothing else changes there
    shutil.copy(noop.Memo(root, "validate", []).path, copied.path)
    assert replays(clone) == (False, "")


def test_a_resealed_memo_of_another_snapshot_is_not_believed(tmp_path: Path) -> None:
    """A memo whose checksum matches but whose snapshot is not this project's (forged by hand)."""
    root = project(tmp_path)
    path = recorded(root).path
    document = noop.unseal(path.read_bytes())
    assert document is not None
    path.write_text(noop.seal({**document, "snapshot": "0" * 64, "stdout": "forged\n"}))
    os.chmod(path, 0o600)
    assert replays(root) == (False, "")


def test_is_private_needs_this_user_and_no_one_else_writing() -> None:
    mine = os.stat_result((stat.S_IFREG | 0o600, 0, 0, 1, os.geteuid(), 0, 0, 0, 0, 0))
    theirs = os.stat_result((stat.S_IFREG | 0o600, 0, 0, 1, os.geteuid() + 1, 0, 0, 0, 0, 0))
    shared = os.stat_result((stat.S_IFREG | 0o664, 0, 0, 1, os.geteuid(), 0, 0, 0, 0, 0))
    assert is_private(mine) and not is_private(theirs) and not is_private(shared)


# ------------------------------------------------------------------------------ racily clean files


class CoarseClock:
    """A file system whose clock ticks every 2 s (FAT's): every time ``os.stat``/``os.lstat`` show is rounded down
    to the tick. (This machine's kernel gives each change after a look a finer time, so two writes never share
    one here; a FAT stick, an SMB share or an older kernel do.)"""

    TICK = 2_000_000_000

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.real_stat, self.real_lstat = os.stat, os.lstat
        monkeypatch.setattr(os, "stat", lambda *a, **k: self.coarse(self.real_stat(*a, **k)))
        monkeypatch.setattr(os, "lstat", lambda *a, **k: self.coarse(self.real_lstat(*a, **k)))

    def coarse(self, st: os.stat_result) -> os.stat_result:
        times = {f"st_{k}time_ns": getattr(st, f"st_{k}time_ns") // self.TICK * self.TICK for k in "amc"}
        return _Stat(st, times)  # type: ignore[return-value]


class _Stat:
    """A stat result with other times (``os.stat_result`` cannot be built with nanosecond times)."""

    def __init__(self, real: os.stat_result, times: dict[str, int]) -> None:
        self._real = real
        for key, value in times.items():
            setattr(self, key, value)
            setattr(self, key[:-3], value / 1e9)

    def __getattr__(self, name: str) -> object:
        return getattr(self._real, name)


def rewritten_within_one_tick(root: Path, node: Path, attempt: int) -> bool:
    """Write ``node``, record the memo, write it again with the same size: True when both writes left the times
    and size the memo's snapshot holds unchanged (they shared a tick of the coarse clock)."""
    node.write_text(f"print({attempt % 10})\n")
    before = os.stat(node)
    recorded(root, f"round {attempt}\n")
    node.write_text(f"print({(attempt + 1) % 10})\n")
    after = os.stat(node)
    return (after.st_mtime_ns, after.st_ctime_ns, after.st_size) == (before.st_mtime_ns, before.st_ctime_ns,
                                                                     before.st_size)


def test_a_file_written_twice_within_one_tick_is_seen(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Write, record the memo, write the same size again: on a file system whose clock ticks every 2 s both
    writes usually share every time the snapshot holds, and only the hash of the young file shows the second."""
    root = project(tmp_path)
    node = root / "src" / "node.py"
    CoarseClock(monkeypatch)
    same_tick = 0
    for attempt in range(20):
        same_tick += rewritten_within_one_tick(root, node, attempt)
        assert replays(root)[0] is False, f"attempt {attempt}: the second write was not seen"
        if same_tick >= 3:
            break
    assert same_tick >= 3, "no two writes shared a tick: the case this test is for did not happen"


def test_without_the_young_files_hash_the_second_write_would_be_missed(tmp_path: Path,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """The negative control of the test above: with no file counted young, the stale memo is believed."""
    root = project(tmp_path)
    node = root / "src" / "node.py"
    CoarseClock(monkeypatch)
    monkeypatch.setattr(noop, "RACY_SECONDS", -60.0)
    for attempt in range(20):
        if rewritten_within_one_tick(root, node, attempt):
            assert replays(root) == (True, f"round {attempt}\n")  # believed: the second write is missed
            return
    pytest.fail("no two writes shared a tick")


def test_young_files_are_hashed_only_while_young(tmp_path: Path) -> None:
    root = project(tmp_path)
    old = os.stat(root / "robot.yaml").st_mtime - 60
    for path in (root / "robot.yaml", root / "src" / "node.py"):
        os.utime(path, (old, old))
    snap = noop.snapshot(root, images=False, young_after=os.stat(root / "robot.yaml").st_ctime + 1)
    assert snap is not None and snap.young == {}
    snap = noop.snapshot(root, images=False, young_after=0)
    assert snap is not None and {"robot.yaml", "src/node.py"} <= set(snap.young)


def test_too_many_young_files_write_no_memo(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    root = project(tmp_path)
    monkeypatch.setattr(trees, "MAX_YOUNG_FILES", 1)
    run = noop.Memo(root, "validate", [])
    assert not run.replay(io.StringIO(), io.StringIO())
    assert run.record("ok\n", "") is False


def test_the_memo_is_private_whatever_the_umask(tmp_path: Path) -> None:
    root = project(tmp_path)
    old = os.umask(0)
    try:
        path = recorded(root).path
    finally:
        os.umask(old)
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    assert stat.S_IMODE(os.stat(path.parent).st_mode) == 0o700
    assert json.loads(path.read_text().split("\n", 1)[1])["stdout"] == "ok\n"
