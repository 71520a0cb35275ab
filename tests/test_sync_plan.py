"""The sync plan: rsync argv, remote scripts as argv, stats parsing, release ids (no I/O)."""

from __future__ import annotations

import os
import shlex
import subprocess
from datetime import datetime, timezone
from pathlib import Path, PurePosixPath

import pytest

from robocore.adapters import ssh
from robocore.config.model import Host
from robocore.plan import sync as plan

HOST = Host(name="robot1", ip="10.0.0.5", user="pi", ssh_port=2222)


def item(tmp: Path) -> plan.ComponentSync:
    return plan.ComponentSync(
        component="talker", host="robot1", root=PurePosixPath("/home/pi/robocore/talker"),
        sources=(plan.Source(tmp / "build" / "talker" / "install", "install"),
                 plan.Source(tmp / "state" / "dds", "dds"),
                 plan.Source(tmp / "state" / "compose" / "robot1.yaml", "robot1.yaml")),
        compose_name="robot1.yaml",
    )


def test_rsync_argv_links_against_current_and_writes_to_staging(tmp_path: Path) -> None:
    argv = plan.rsync_argv(item(tmp_path), HOST, "ssh -p 2222")
    assert argv[0] == "rsync"
    assert "--link-dest=/home/pi/robocore/talker/current/" in argv
    assert argv[-1] == "pi@10.0.0.5:/home/pi/robocore/talker/staging/"
    assert f"{tmp_path}/build/talker/./install" in argv
    assert f"{tmp_path}/state/compose/./robot1.yaml" in argv
    assert {"-a", "-R", "--delete", "--stats", "--copy-unsafe-links"} <= set(argv)
    assert argv[argv.index("-e") + 1] == "ssh -p 2222"


def test_remote_steps_are_fixed_scripts_with_arguments_as_argv(tmp_path: Path) -> None:
    evil = plan.ComponentSync(component="x", host="h", root=PurePosixPath("/tmp/a b;touch /tmp/pwned"),
                              sources=(), compose_name="h.yaml")
    argv = plan.session_argv("/srv/$(id)", "me; rm -rf /", [evil], keep=2)
    assert argv[:2] == ["sh", "-c"] and argv[2] == plan.SESSION_SCRIPT
    assert argv[3:] == ["sh", "/srv/$(id)", "me; rm -rf /", "2", "/tmp/a b;touch /tmp/pwned", "h.yaml"]
    assert plan.finish_line("20260101T000000Z-abcdef", [plan.RELEASE, plan.KEEP]) == (
        "20260101T000000Z-abcdef release keep")
    with pytest.raises(ValueError):
        plan.finish_line("../../etc", [plan.RELEASE])
    with pytest.raises(ValueError):
        plan.finish_line("20260101T000000Z-abcdef", ["release; rm -rf /"])


def test_ssh_quotes_every_remote_argument() -> None:
    argv = ssh.ssh_argv(HOST, ["echo", "a b", "$(id)", "'q'"])
    assert argv[0] == "ssh" and "-p" in argv and argv[argv.index("-p") + 1] == "2222"
    assert "BatchMode=yes" in argv
    assert argv[-2] == "pi@10.0.0.5"
    assert shlex.split(argv[-1]) == ["echo", "a b", "$(id)", "'q'"]


class LocalSession:
    """The real session script, run locally with sh (the remote side of a sync, without ssh)."""

    def __init__(self, mount_root: Path, items: list[plan.ComponentSync], holder: str = "test", keep: int = 3) -> None:
        self.proc = subprocess.Popen(plan.session_argv(str(mount_root), holder, items, keep=keep),
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.greeting = self.read_until(plan.LOCKED)

    def read_until(self, marker: str) -> list[str]:
        assert self.proc.stdout is not None
        lines = []
        while (line := self.proc.stdout.readline()) and line.strip() != marker:
            lines.append(line.strip())
        assert line, f"the session ended before {marker}: {lines} {self.proc.stderr.read() if self.proc.stderr else ''}"
        return lines

    def finish(self, line: str) -> int:
        assert self.proc.stdin is not None
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()
        self.read_until(plan.DONE)
        self.proc.stdin.close()
        return self.proc.wait(timeout=10)

    def hang_up(self) -> int:
        assert self.proc.stdin is not None
        self.proc.stdin.close()
        return self.proc.wait(timeout=10)


def test_the_session_switches_current_atomically_and_prunes(tmp_path: Path) -> None:
    """Run the real script locally with sh: the layout it leaves is the contract with run."""
    roots = [tmp_path / "robot" / "talker", tmp_path / "robot" / "odd name;x"]
    items = [plan.ComponentSync(component=r.name, host="h", root=PurePosixPath(str(r)), sources=(),
                                compose_name="h.yaml") for r in roots]
    ids: list[str] = []
    for n in range(5):
        session = LocalSession(tmp_path / "robot", items)
        for keys in plan.parse_prepare(session.greeting, len(items)):
            assert keys["staging"] == "0"
            assert keys["current"] == ("" if n == 0 else f"releases/{ids[-1]}")
        for root in roots:
            (root / "staging" / "install").mkdir(parents=True)  # what rsync writes
            (root / "staging" / "install" / "v").write_text(str(n))
            (root / "staging" / "h.yaml").write_text("services: {}\n")
        rid = plan.new_release_id(datetime(2026, 1, 1, 0, 0, n, tzinfo=timezone.utc), nonce=bytes([n]))
        ids.append(rid)
        assert session.finish(plan.finish_line(rid, [plan.RELEASE, plan.RELEASE])) == 0
        for root in roots:
            assert (root / "current").is_symlink() and (root / "current" / "install" / "v").read_text() == str(n)
            assert (root / "current" / "compose.yaml").read_text() == "services: {}\n"
            assert not (root / "staging").exists()
    for root in roots:
        assert sorted(p.name for p in (root / "releases").iterdir()) == ids[-3:]
    # robocore went away mid-copy: nothing is switched, and the next session reports the copy
    (roots[0] / "staging").mkdir()
    assert LocalSession(tmp_path / "robot", items).hang_up() == 0
    session = LocalSession(tmp_path / "robot", items[:1])
    assert plan.parse_prepare(session.greeting, 1) == [{"staging": "1", "current": f"releases/{ids[-1]}"}]
    # an unchanged copy is discarded, a kept component is left as it is
    assert session.finish(plan.finish_line(plan.new_release_id(), [plan.DISCARD])) == 0
    assert not (roots[0] / "staging").exists() and (roots[0] / "current" / "install" / "v").read_text() == "4"
    (roots[1] / "staging").mkdir()
    assert LocalSession(tmp_path / "robot", items).finish(plan.finish_line(plan.new_release_id(),
                                                                           [plan.KEEP, plan.KEEP])) == 0
    assert (roots[1] / "staging").is_dir() and os.readlink(roots[1] / "current") == f"releases/{ids[-1]}"


def test_the_session_refuses_an_unknown_step(tmp_path: Path) -> None:
    item = plan.ComponentSync(component="a", host="h", root=PurePosixPath(str(tmp_path / "a")), sources=(),
                              compose_name="")
    session = LocalSession(tmp_path, [item])
    assert session.proc.stdin is not None and session.proc.stderr is not None
    session.proc.stdin.write("20260101T000000Z-abcdef rm\n")
    session.proc.stdin.close()
    assert session.proc.wait(timeout=10) == 64 and "unknown step" in session.proc.stderr.read()
    assert not (tmp_path / "a" / "current").exists()


def test_parse_stats_reads_rsync_3_output() -> None:
    text = """
Number of files: 1,234 (reg: 1,000, dir: 234)
Number of created files: 2 (reg: 2)
Number of deleted files: 0
Number of regular files transferred: 3
Total file size: 5,000,000 bytes
Literal data: 1,024 bytes
Total bytes sent: 12,345
Total bytes received: 678
"""
    stats = plan.parse_stats(text)
    assert (stats.files, stats.created, stats.transferred, stats.literal, stats.sent, stats.received) == (
        1234, 2, 3, 1024, 12345, 678)
    assert stats.changed
    assert not plan.parse_stats("Number of files: 5\nTotal bytes sent: 90\n").changed


def test_release_ids_sort_by_time_and_are_validated() -> None:
    a = plan.new_release_id(datetime(2026, 1, 1, 12, 0, 0, tzinfo=timezone.utc), nonce=b"x")
    b = plan.new_release_id(datetime(2026, 1, 1, 12, 0, 1, tzinfo=timezone.utc), nonce=b"a")
    assert a < b and plan.is_release_id(a) and a.startswith("20260101T120000Z-")
    assert not plan.is_release_id("current") and not plan.is_release_id("20260101T120000Z-zz/..")


def test_manifest_digest_sees_size_time_and_deletions() -> None:
    rows = [("install/a", 1, 10, 0o644, ""), ("install/b", 2, 20, 0o644, "")]
    base = plan.manifest_digest(rows)
    assert plan.manifest_digest(list(reversed(rows))) == base
    assert plan.manifest_digest(rows[:1]) != base
    assert plan.manifest_digest([rows[0], ("install/b", 2, 21, 0o644, "")]) != base


def test_the_sync_lock_admits_one_holder_and_names_it_to_the_next(tmp_path: Path) -> None:
    """The real session script, run locally with sh: a second taker is refused at once with the first's line."""
    root = tmp_path / "robot root;$(touch pwned)"
    first = LocalSession(root, [], holder="alice@laptop (pid 1)")
    second = subprocess.run(plan.session_argv(str(root), "bob", []), stdin=subprocess.DEVNULL, capture_output=True,
                            text=True, timeout=10)
    assert second.returncode == plan.LOCK_BUSY and second.stdout == ""
    assert second.stderr.strip() == "alice@laptop (pid 1)"
    assert first.hang_up() == 0
    third = LocalSession(root, [], holder="bob")
    assert third.greeting == [] and third.hang_up() == 0
    assert not (tmp_path / "pwned").exists() and not Path("pwned").exists()


def test_a_failed_remote_script_is_named_in_one_short_line() -> None:
    failed = subprocess.CompletedProcess(["ssh"], 1, b"", b"some noise\nmv: cannot move 'staging': Permission denied\n")
    line = ssh.describe_failure(failed, plan.session_argv("/srv/robocore", "me", []))
    assert "\n" not in line and len(line) < 160
    assert line.endswith("exited 1: mv: cannot move 'staging': Permission denied")
    assert ssh.describe_failure(failed, ["docker", "version"]).startswith("`docker version` exited 1")
