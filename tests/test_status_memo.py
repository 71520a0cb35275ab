"""status's fast path: an unchanged all-local project prints its table from the recorded plan and the daemon.

Controls: a changed file, a flag, a daemon that does not answer, a memo that does not match the project's
snapshot (one that came with a clone) or holds no valid plan: each takes the ordinary path, printing nothing.
"""

from __future__ import annotations

import io
import json
import os
import time
from contextlib import redirect_stdout
from pathlib import Path
from typing import Any

import pytest

from robocore.adapters import docker_socket
from robocore.commands.support import noop, status_memo
from robocore.commands.support.status_table import NOT_ASKED, host_rows, print_status

PLANNED = ["discovery-0", "talker", "listener"]


def document(name: str, role: str = "component", *, running: bool = True,
             started: str = "2026-11-25T10:00:05.1Z") -> dict[str, Any]:
    """A container's inspect document as the daemon gives it."""
    return {"Name": f"/robot-{name}", "RestartCount": 0,
            "State": {"Status": "running" if running else "exited", "StartedAt": started},
            "Config": {"Image": f"robot-{name}:latest",
                       "Labels": {"dev.robocore.project": "robot", "dev.robocore.component": name,
                                  "dev.robocore.role": role}}}


@pytest.fixture
def project(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A project folder (the current folder, with robocore's records folder) whose files are a minute old."""
    root = tmp_path / "robot"
    (root / ".robocore").mkdir(parents=True)
    (root / "robot.yaml").write_text("ros_distro: jazzy\n")
    old = time.time() - 60
    os.utime(root / "robot.yaml", (old, old))
    monkeypatch.chdir(root)
    monkeypatch.delenv(noop.DISABLE, raising=False)
    return root


def record(servers: list[str] | None = None, *, register_once: bool = False) -> None:
    """What an ordinary ``status`` does: the snapshot first, then the plan kept."""
    memo = status_memo.memo_for(["status"])
    assert memo is not None
    memo.started += 2 * noop.RACY_SECONDS
    memo.current()
    status_memo.record(memo, status_memo.plan_document(
        "robot", [("dev", PLANNED)], servers or ["discovery-0"], register_once=register_once))


def answered(monkeypatch: pytest.MonkeyPatch, documents: list[dict[str, Any]] | None) -> tuple[bool, str]:
    asked: list[str] = []

    def containers(label: str, **_: Any) -> list[dict[str, Any]] | None:
        asked.append(label)
        return documents

    monkeypatch.setattr(docker_socket, "containers", containers)
    out = io.StringIO()
    with redirect_stdout(out):
        done = status_memo.answer(["status"])
    assert asked in ([], ["dev.robocore.project=robot"])
    return done, out.getvalue()


def table(documents: list[dict[str, Any]]) -> str:
    out = io.StringIO()
    with redirect_stdout(out):
        print_status(host_rows("dev", PLANNED, documents), {}, None, NOT_ASKED)
    return out.getvalue()


@pytest.mark.parametrize(("args", "plain"), [
    (["status"], True), (["-p", "{root}", "status"], True), (["{root}", "status"], True),
    (["--project={root}", "status"], True), (["status", "--json"], False), (["status", "--nodes"], False),
    (["status", "--dry-run"], False), (["status", "-d"], False), (["validate"], False), (["logs"], False),
])
def test_only_a_plain_status_line_has_a_fast_path(project: Path, args: list[str], plain: bool) -> None:
    memo = status_memo.memo_for([a.format(root=project) for a in args])
    assert (memo is not None) == plain
    if memo is not None:
        assert memo.project == project and memo.path.name.startswith("status-")


def test_an_unchanged_project_prints_the_ordinary_table(project: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    documents = [document("talker"), document("discovery-0", "discovery"), document("shell", "shell"),
                 document("old", running=False)]
    assert answered(monkeypatch, documents) == (False, "")  # nothing recorded yet
    record()
    done, printed = answered(monkeypatch, documents)
    assert done
    assert printed == table([d for d in documents if d["Config"]["Labels"]["dev.robocore.role"] != "shell"])
    lines = printed.splitlines()
    assert any("talker" in line and "running" in line for line in lines)
    assert any("listener" in line and "missing" in line for line in lines)
    assert any("old" in line and "exited (not planned)" in line for line in lines)
    assert not any("shell" in line for line in lines)  # a dev shell is not the robot's
    assert lines[-1].startswith("ROS nodes: not asked")


def test_a_node_older_than_the_master_is_named(project: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    record(["discovery-0"], register_once=True)
    documents = [document("discovery-0", "discovery", started="2026-11-25T10:00:05Z"),
                 document("talker", started="2026-11-25T09:00:00Z"), document("listener")]
    done, printed = answered(monkeypatch, documents)
    assert done
    assert printed.splitlines()[-1].startswith("not registered with the ROS master, which started again after "
                                               "them: talker ")


@pytest.mark.parametrize("change", ["touch", "edit", "add"])
def test_a_change_takes_the_ordinary_path(project: Path, monkeypatch: pytest.MonkeyPatch, change: str) -> None:
    record()
    if change == "touch":  # the same content, new times
        os.utime(project / "robot.yaml")
    elif change == "edit":
        (project / "robot.yaml").write_text("ros_distro: kilted\n")
    else:
        (project / "components").mkdir()
    assert answered(monkeypatch, [document("talker")]) == (False, "")


def test_a_daemon_that_does_not_answer_takes_the_ordinary_path(project: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    record()
    assert answered(monkeypatch, None) == (False, "")


def test_the_memo_can_be_disabled(project: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    record()
    monkeypatch.setenv(noop.DISABLE, "1")
    assert answered(monkeypatch, [document("talker")]) == (False, "")


@pytest.mark.parametrize("content", [
    {"snapshot": "0" * 64, "project": "robot", "hosts": [["dev", ["evil"]]], "servers": [], "register_once": False},
    "not json",
])
def test_a_memo_that_does_not_match_the_project_is_never_read(project: Path, monkeypatch: pytest.MonkeyPatch,
                                                              content: Any) -> None:
    """A memo that came with the project's files (a clone): its snapshot cannot be the fresh one."""
    memo = status_memo.memo_for(["status"])
    assert memo is not None
    memo.path.parent.mkdir()
    memo.path.write_text(json.dumps(content) if isinstance(content, dict) else content)
    assert answered(monkeypatch, [document("talker")]) == (False, "")


@pytest.mark.parametrize("plan", [
    {"project": 5, "hosts": [], "servers": []},
    {"project": "robot", "hosts": [["dev"]], "servers": []},
    {"project": "robot", "hosts": [["dev", [1]]], "servers": []},
    {"project": "robot", "hosts": [["dev", ["talker"]]], "servers": None},
])
def test_a_matching_memo_without_a_valid_plan_takes_the_ordinary_path(project: Path, monkeypatch: pytest.MonkeyPatch,
                                                                     plan: dict[str, Any]) -> None:
    memo = status_memo.memo_for(["status"])
    assert memo is not None
    memo.started += 2 * noop.RACY_SECONDS
    memo.current()
    assert memo.keep(plan)
    assert answered(monkeypatch, [document("talker")]) == (False, "")


def test_a_resealed_plan_is_read_and_a_broken_seal_is_dropped(project: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """What integration/test_run_local.py does by hand: a plan edited and resealed is the one printed (the memo is
    read), an edit that breaks the checksum is dropped and the ordinary path runs."""
    record()
    memo = status_memo.memo_for(["status"])
    assert memo is not None
    plan = noop.unseal(memo.path.read_bytes())
    assert plan is not None
    plan["hosts"][0][1].append("ghost")  # type: ignore[index]
    memo.path.write_text(noop.seal(plan))
    done, printed = answered(monkeypatch, [document("talker")])
    assert done and any("ghost" in line and "missing" in line for line in printed.splitlines())
    memo.path.write_text(noop.seal(plan).replace("ghost", "other"))
    assert answered(monkeypatch, [document("talker")]) == (False, "")
    assert not memo.path.exists()
