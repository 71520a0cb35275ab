"""robocore's state is private whatever the umask. Under ``.robocore/`` every folder robocore creates is
0700 and every file 0600, except the few another user reads (0755 folders, 0644 files: ``files.SHARED``): the DDS
profiles and the dev shell's start files (mounted into containers whose user may not be the invoking one) and the
trees sent to robot hosts as they are (a component's ``install`` folder, the ``sync`` folder). Nothing robocore
creates may be written by another user.

Each task that writes without a Docker daemon runs here as a user would, under ``umask 000``; the writes of the
tasks that need a daemon (build records, sync records, run history, the ssh hosts record)
go through the same helpers, called here with the umask set to 000 too.
"""

from __future__ import annotations

import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from robocore import files
from robocore.commands.support import state
from robocore.config.loader import parse_robot_text
from robocore.project import Project

ROBOT = ("ros_distro: jazzy\nhosts:\n  - {name: dev, ip: 192.168.1.10}\n"
         "  - {name: pi, ip: 192.168.1.20}\n"
         "components:\n  - {name: talker, runs_on: pi, image: 'vendor/talker:1', environment: {TOKEN: s3cret}}\n")
#: Folders under .robocore that another user reads (0755), by name, and the files in them (0644).
SHARED_FOLDERS = {"dds", "shell", "install"}


def modes(root: Path) -> dict[str, int]:
    out = {}
    for here, dirs, names in os.walk(root / files.STATE_DIR):
        for name in [*dirs, *names]:
            path = Path(here) / name
            out[path.relative_to(root).as_posix()] = stat.S_IMODE(os.lstat(path).st_mode)
    return out


def check(root: Path) -> None:
    found = modes(root)
    assert found, "the task wrote nothing under .robocore"
    for rel, mode in found.items():
        parts = rel.split("/")
        shared = bool(SHARED_FOLDERS & set(parts[1:]))
        if (root / rel).is_dir():
            assert mode == (files.SHARED_DIR if parts[-1] in SHARED_FOLDERS else files.PRIVATE_DIR), (rel, oct(mode))
        else:
            assert mode == (files.SHARED if shared and not rel.endswith(".lock") else files.PRIVATE), (rel, oct(mode))
    assert stat.S_IMODE(os.stat(root / files.STATE_DIR).st_mode) == files.PRIVATE_DIR


def robocore(cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    done = subprocess.run([sys.executable, "-m", "robocore", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=300, stdin=subprocess.DEVNULL, preexec_fn=lambda: os.umask(0),
                          env={**os.environ, "DOCKER_HOST": f"unix://{cwd}/nobody.sock"})
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    return done


def test_init_validate_and_stage_refresh_under_umask_000(tmp_path: Path) -> None:
    robocore(tmp_path, "init", "robot", "--defaults")
    root = tmp_path / "robot"
    check(root)  # init: the JSON Schema
    robocore(root, "validate")
    robocore(root, "validate")  # the no-op memo
    assert list((root / ".robocore" / "noop").iterdir())
    robocore(root, "stage", "--refresh")  # compose files (environment values) and DDS profiles
    assert (root / ".robocore" / "dds").is_dir()
    check(root)


@pytest.fixture
def umask_000(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(files, "UMASK", 0)
    old = os.umask(0)
    yield
    os.umask(old)


@pytest.mark.usefixtures("umask_000")
def test_the_records_of_tasks_that_need_a_daemon_under_umask_000(tmp_path: Path) -> None:
    root = tmp_path / "robot"
    root.mkdir()
    (root / "robot.yaml").write_text(ROBOT)
    project = Project(root=root, robot=parse_robot_text(ROBOT))
    state.write_build_state(project.build_state_file("talker"), {"packages": {}})  # build
    state.write_synced(project, "pi", {"talker": {"digest": "x"}})  # sync
    state.record_run(project, project.robot.hosts[1], None)  # run
    files.make_folder(project.build_dir("talker") / "install", shared=True)  # build's mounts
    files.write_atomic(project.build_dir("talker") / "install" / "arch", "amd64\n", mode=files.SHARED)
    files.write_atomic(project.ssh_hosts_record, "[]")  # the ssh warm-up
    check(root)


@pytest.mark.usefixtures("umask_000")
def test_folders_made_loose_before_are_narrowed(tmp_path: Path) -> None:
    """A state folder made by an older robocore under a loose umask loses the bits that let others write."""
    root = tmp_path / "robot"
    (root / ".robocore" / "history").mkdir(parents=True)
    os.chmod(root / ".robocore", 0o775)  # umask 002, common with a group per user
    os.chmod(root / ".robocore" / "history", 0o777)
    files.write_atomic(root / ".robocore" / "history" / "pi.json", "[]")
    assert stat.S_IMODE(os.stat(root / ".robocore" / "history").st_mode) == 0o755
    assert stat.S_IMODE(os.stat(root / ".robocore").st_mode) == 0o755  # the memo trusts no group-writable folder
    assert stat.S_IMODE(os.stat(root / ".robocore" / "history" / "pi.json").st_mode) == files.PRIVATE


@pytest.mark.usefixtures("umask_000")
def test_files_outside_the_state_folder_are_never_writable_by_others(tmp_path: Path) -> None:
    files.write_atomic(tmp_path / "a" / "compose.yaml", "x")
    assert stat.S_IMODE(os.stat(tmp_path / "a" / "compose.yaml").st_mode) == 0o644
    assert stat.S_IMODE(os.stat(tmp_path / "a").st_mode) == 0o755
