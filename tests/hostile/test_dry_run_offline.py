"""``--dry-run`` is offline: every task prints its plan, exits 0, writes nothing and contacts nothing.

``DOCKER_HOST`` points at a Unix socket this test listens on (a connection would show), and ``ssh``,
``rsync``, ``git`` and ``docker`` on PATH are fakes that leave a mark when run. The project has a
record of its ssh hosts, so that the command's early warm-up would connect if it did not see the dry
run. Negative controls: the same set-up without ``--dry-run`` does connect, and does run ssh.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
from conftest import built_project

from robocore.commands.support import warmup

ROBOT_YAML = """\
ros_distro: jazzy
base: {kind: wheels}
registry: registry.example:5000
hosts:
  - {name: main, ip: "10.99.0.1", user: robot}
  - {name: dev, ip: 127.0.0.1, user: me}
components:
  - {name: talker, folder: components/talker, runs_on: main}
  - {name: listener, folder: components/listener, runs_on: dev}
"""

TASKS = [
    (["validate", "--dry-run"], "would validate"),
    (["prepare-base", "--dry-run"], "unknown (dry run: not contacted)"),
    (["stage", "-d"], "unknown (dry run: not contacted)"),
    (["build", "--dry-run"], "colcon"),
    (["sync", "--dry-run"], "rsync -a -R -s"),
    (["run", "-d"], "unknown (dry run: not contacted)"),
    (["run", "--dry-run", "--tag", "v1"], "unknown (dry run: not contacted)"),
    (["down", "--dry-run"], "which ones: unknown (dry run: not contacted)"),
    (["status", "-d"], "would list"),
    (["logs", "--dry-run", "--tail", "5"], "would read logs"),
    (["shell", "--component", "listener", "--dry-run"], '"container":'),
    (["connect", "--component", "talker", "-d"], "on main (interactive)"),
    (["release", "--dry-run", "--tag", "v1"], "docker push registry.example:5000/"),
    (["rollback", "--dry-run"], "main: would run tag v0"),
    # the flag after the last task makes the whole line a dry run (invoke alone would give it to run only)
    (["build", "sync", "run", "--dry-run"], "rsync -a -R -s"),
    (["stage", "build", "sync", "run", "-d"], "unknown (dry run: not contacted)"),
    (["build", "--dry-run", "sync", "run"], "rsync -a -R -s"),
]


@pytest.fixture
def world(tmp_path: Path) -> Iterator[dict[str, object]]:
    root = tmp_path / "robot"
    project = built_project(root, ROBOT_YAML)
    history = project.state_dir / "history" / "main.json"
    history.parent.mkdir(parents=True)
    runs = [{"tag": "v0", "releases": {}}, {"tag": "v1", "releases": {}}]
    history.write_text(json.dumps({"host": "main", "runs": runs}))
    warmup.record_warmed(root, [warmup.Endpoint("main", "robot", "10.99.0.1", 22)])  # the next command would warm it
    fake_bin = tmp_path / "bin"
    fake_bin.mkdir()
    for tool in ("ssh", "rsync", "git", "docker", "mmdebstrap"):
        (fake_bin / tool).write_text(f'#!/bin/sh\ntouch "{tmp_path}/ran-{tool}"\nexit 255\n')
        (fake_bin / tool).chmod(0o755)
    sock_path = tmp_path / "docker.sock"
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    listener.bind(str(sock_path))
    listener.listen(16)
    listener.setblocking(False)
    env = {k: v for k, v in os.environ.items() if k != "XDG_RUNTIME_DIR"}
    env.update(PATH=f"{fake_bin}:{env['PATH']}", DOCKER_HOST=f"unix://{sock_path}", TMPDIR=str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    yield {"root": root, "tmp": tmp_path, "env": env, "listener": listener}
    listener.close()


def snapshot(folder: Path) -> list[tuple[str, int, int]]:
    return sorted((str(p.relative_to(folder)), p.lstat().st_mtime_ns, p.lstat().st_mode) for p in folder.rglob("*"))


def connections(listener: socket.socket) -> int:
    count = 0
    while True:
        try:
            conn, _ = listener.accept()
        except BlockingIOError:
            return count
        conn.close()
        count += 1


def robocore(world: dict[str, object], *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "robocore", "-p", str(world["root"]), *args], capture_output=True,
                          text=True, env=world["env"], timeout=120)  # type: ignore[arg-type]


@pytest.mark.parametrize("argv, says", TASKS, ids=lambda v: " ".join(v) if isinstance(v, list) else None)
def test_dry_run_prints_the_plan_offline(argv: list[str], says: str, world: dict[str, object]) -> None:
    root, tmp = Path(str(world["root"])), Path(str(world["tmp"]))
    before = snapshot(tmp)
    done = robocore(world, *argv)
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    assert says in done.stdout + done.stderr, done.stdout + done.stderr
    assert connections(world["listener"]) == 0, "the Docker daemon was contacted"  # type: ignore[arg-type]
    assert not list(tmp.glob("ran-*")), [p.name for p in tmp.glob("ran-*")]
    assert snapshot(tmp) == before, "files were written"
    assert root.exists()


def test_a_dry_run_line_with_a_task_that_has_none_is_refused(world: dict[str, object]) -> None:
    tmp = Path(str(world["tmp"]))
    before = snapshot(tmp)
    done = robocore(world, "stage", "--dry-run", "doctor")
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.count("\n") == 1 and "doctor has no dry run" in done.stderr, done.stderr
    assert connections(world["listener"]) == 0  # type: ignore[arg-type]
    assert snapshot(tmp) == before and not list(tmp.glob("ran-*"))


def test_negative_control_without_dry_run_the_daemon_and_ssh_are_contacted(world: dict[str, object]) -> None:
    """The same checks catch a real run: a prepare-base reaches the socket, a status starts ssh."""
    listener: socket.socket = world["listener"]  # type: ignore[assignment]
    seen: list[int] = []
    stop = threading.Event()

    def hang_up() -> None:  # accept and close every connection, so that clients fail at once instead of waiting
        listener.settimeout(0.1)
        while not stop.is_set():
            try:
                conn, _ = listener.accept()
            except OSError:
                continue
            conn.close()
            seen.append(1)

    thread = threading.Thread(target=hang_up)
    thread.start()
    try:
        done = robocore(world, "prepare-base")
        assert seen and done.returncode != 0 and "Traceback" not in done.stderr
        robocore(world, "status")
    finally:
        stop.set()
        thread.join()
        listener.setblocking(False)
    assert (Path(str(world["tmp"])) / "ran-ssh").exists()
