"""The no-op memo: an unchanged project replays the last no-op's output; every real change takes the ordinary path.

The snapshot is stat-based, so the controls here are the changes a stat could miss: a file touched with
identical content (the ordinary path runs, then records again), a change inside a symlinked folder, a file
added there, a symlink retargeted, robocore's own records in ``.robocore`` removed, a run that changed
something, and a file too recent to trust.
"""

from __future__ import annotations

import io
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from robocore.commands.support import noop


def make(tmp_path: Path) -> tuple[Path, Path]:
    """A project whose component folder is a symlink to another folder inside it (``vendor/ws``)."""
    root = tmp_path / "robot"
    outside = root / "vendor" / "ws"
    (outside / "src" / "pkg").mkdir(parents=True)
    (outside / "src" / "pkg" / "node.py").write_text("print('hello')\n")
    (root / "components").mkdir(parents=True)
    (root / "robot.yaml").write_text("ros_distro: jazzy\n")
    (root / "components" / "talker").symlink_to("../vendor/ws", target_is_directory=True)
    (root / ".robocore" / "build" / "talker" / "install").mkdir(parents=True)
    return root, outside


def memo(root: Path) -> noop.Memo:
    made = noop.Memo(root, "validate", [])
    made.started += 2 * noop.RACY_SECONDS  # as if the command ran a little later than the files were made
    return made


def replayed(root: Path) -> tuple[bool, str]:
    out, err = io.StringIO(), io.StringIO()
    done = memo(root).replay(out, err)
    return done, out.getvalue() + err.getvalue()


def recorded(root: Path, text: str = "ok\n") -> bool:
    """The ordinary path: a run that changed nothing, then its record."""
    run = memo(root)
    assert not run.replay(io.StringIO(), io.StringIO())
    return run.record(text, "")


def test_an_unchanged_project_replays_the_recorded_output(tmp_path: Path) -> None:
    root, _ = make(tmp_path)
    assert replayed(root) == (False, "")
    assert recorded(root, "robot.yaml: ok\n")
    assert replayed(root) == (True, "robot.yaml: ok\n")
    assert replayed(root) == (True, "robot.yaml: ok\n")


def test_a_touched_identical_file_takes_the_ordinary_path_once(tmp_path: Path) -> None:
    root, _ = make(tmp_path)
    assert recorded(root)
    later = time.time() - 30
    os.utime(root / "robot.yaml", (later, later))  # same content, new time
    assert replayed(root)[0] is False
    assert recorded(root)  # the ordinary path found nothing to do: recorded again
    assert replayed(root)[0] is True


@pytest.mark.parametrize("change", ["edit", "same_size_same_mtime", "add", "remove", "retarget"])
def test_a_change_inside_a_symlinked_folder_is_seen(tmp_path: Path, change: str) -> None:
    root, outside = make(tmp_path)
    assert recorded(root)
    node = outside / "src" / "pkg" / "node.py"
    if change == "edit":
        node.write_text("print('hello, world')\n")
    elif change == "same_size_same_mtime":
        before = node.stat()
        node.write_text("print('HELLO')\n")
        os.utime(node, ns=(before.st_atime_ns, before.st_mtime_ns))  # only the change time shows it
    elif change == "add":
        (outside / "src" / "pkg" / "other.py").write_text("")
    elif change == "remove":
        node.unlink()
    else:
        other = tmp_path / "other"
        other.mkdir()
        (root / "components" / "talker").unlink()
        (root / "components" / "talker").symlink_to(other, target_is_directory=True)
    assert replayed(root)[0] is False


def test_robocores_records_count_but_the_memos_do_not(tmp_path: Path) -> None:
    root, _ = make(tmp_path)
    assert recorded(root)
    assert (root / ".robocore" / "noop").is_dir()
    assert replayed(root)[0] is True  # the memo folder itself is not part of the snapshot
    (root / ".robocore" / "build" / "talker" / "install").rmdir()
    assert replayed(root)[0] is False


def test_a_run_that_changed_something_is_not_recorded(tmp_path: Path) -> None:
    root, _ = make(tmp_path)
    run = memo(root)
    run.replay(io.StringIO(), io.StringIO())
    (root / ".robocore" / "build" / "talker" / "state.json").write_text("{}")  # what a real build leaves
    assert run.record("built talker\n", "") is False
    assert replayed(root)[0] is False


def test_a_memo_of_young_files_is_written_and_replayed(tmp_path: Path) -> None:
    """Files made just now (racily clean) are hashed into the memo instead of keeping it from being written."""
    root, _ = make(tmp_path)
    run = noop.Memo(root, "validate", [])
    run.replay(io.StringIO(), io.StringIO())
    assert run.record("ok\n", "")
    assert "robot.yaml" in noop.unseal(run.path.read_bytes())["young"]  # type: ignore[operator]
    again = noop.Memo(root, "validate", [])
    assert again.replay(io.StringIO(), io.StringIO())


@pytest.mark.parametrize(("args", "task"), [
    (["validate"], "validate"), (["stage", "--quiet"], "stage"), (["build", "--component", "talker"], "build"),
    (["build", "--component=talker", "-q"], "build"), (["-p", "{root}", "build"], "build"),
    (["{root}", "stage"], "stage"), (["--project={root}", "validate"], "validate"),
    (["build", "--full"], None), (["stage", "--force"], None), (["validate", "--json"], None),
    (["build", "--dry-run"], None), (["run"], None), (["status"], None), ([], None),
])
def test_only_plain_command_lines_are_memoised(tmp_path: Path, args: list[str], task: str | None) -> None:
    root, _ = make(tmp_path)
    found = noop.command([a.format(root=root) for a in args], root)
    assert (found[1] if found else None) == task


def test_a_folder_without_robot_yaml_is_not_memoised(tmp_path: Path) -> None:
    assert noop.command(["validate"], tmp_path) is None


def test_the_command_replays_validate_and_sees_an_edit(tmp_path: Path) -> None:
    """End to end through ``python -m robocore``: the second run answers from the memo with the same output;
    a broken robot.yaml then fails, as it must."""
    root = tmp_path / "robot"
    root.mkdir()
    text = ("ros_distro: jazzy\nhosts:\n  - name: dev\n    ip: 127.0.0.1\n    docker: local\n"
            "components:\n  - name: talker\n    runs_on: dev\n    image: vendor/talker:1\n")
    (root / "robot.yaml").write_text(text)

    def validate() -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "robocore", "validate"], cwd=root, capture_output=True,
                              text=True, timeout=60)

    first = validate()
    if first.returncode != 0:
        pytest.fail(first.stderr)
    assert len(list((root / ".robocore" / "noop").glob("validate-*.json"))) == 1
    second = validate()
    assert (second.returncode, second.stdout, second.stderr) == (0, first.stdout, first.stderr)
    (root / "robot.yaml").write_text(text.replace("runs_on: dev", "runs_on: nowhere"))
    broken = validate()
    assert broken.returncode != 0 and "unknown host 'nowhere'" in broken.stderr


def test_a_replay_imports_only_what_it_needs(tmp_path: Path) -> None:
    """A replay answers in a few tens of milliseconds because it imports neither robot.yaml's model nor invoke,
    nor typing (about as much work as the whole snapshot); the ordinary run, the negative control, does."""
    root = tmp_path / "robot"
    root.mkdir()
    (root / "robot.yaml").write_text("ros_distro: jazzy\nhosts:\n  - name: dev\n    ip: 127.0.0.1\n")
    code = ("import sys\nsys.argv = ['robocore', 'validate']\nfrom robocore.cli import main\n"
            "try:\n    main()\nfinally:\n    heavy = ('typing', 'pydantic', 'invoke', 'yaml')\n"
            "    print('LOADED=' + ','.join(m for m in heavy if m in sys.modules))\n")

    def loaded() -> str:
        done = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, timeout=60)
        assert done.returncode == 0, done.stderr
        return done.stdout.strip().splitlines()[-1]

    assert loaded() == "LOADED=typing,pydantic,invoke,yaml"  # the ordinary path, which records the memo
    assert loaded() == "LOADED="


def test_the_cli_asks_the_memo_about_every_memoised_task() -> None:
    from robocore import cli

    assert set(noop.TASKS) == set(cli.MEMO_TASKS)
