"""ssh's control-socket folder: robocore's own and private, or not used at all (ssh would otherwise connect
through a socket that another user planted in a folder made beforehand)."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from robocore.adapters import rsync, ssh
from robocore.config.model import Host
from robocore.errors import UnsafePath

HOST = Host(name="robot1", ip="10.0.0.5", user="pi")


@pytest.fixture
def tmp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The temp folder robocore uses (no XDG_RUNTIME_DIR), and fake ssh/rsync that leave a mark when run."""
    folder = tmp_path / "tmp"
    folder.mkdir()
    monkeypatch.setattr("tempfile.tempdir", str(folder))
    monkeypatch.delenv("XDG_RUNTIME_DIR", raising=False)
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for tool in ("ssh", "rsync"):
        fake = bin_dir / tool
        fake.write_text(f'#!/bin/sh\ntouch "{tmp_path}/ran-{tool}"\nexit 0\n')
        fake.chmod(0o755)
    monkeypatch.setenv("PATH", f"{bin_dir}:{os.environ['PATH']}")
    return folder


def expected(tmp: Path) -> Path:
    return tmp / f"robocore-ssh-{os.getuid()}"


def test_a_new_folder_is_private(tmp: Path) -> None:
    path = ssh.ensure_control_dir()
    assert path == expected(tmp) == ssh.control_dir()
    info = path.lstat()
    assert stat.S_ISDIR(info.st_mode) and stat.S_IMODE(info.st_mode) == 0o700 and info.st_uid == os.getuid()
    assert ssh.ensure_control_dir() == path  # and it is used again


def test_only_the_argv_names_it_nothing_is_created_before_ssh_runs(tmp: Path) -> None:
    argv = ssh.ssh_argv(HOST, ["true"])
    assert f"ControlPath={expected(tmp)}/%C" in argv
    assert not expected(tmp).exists()


@pytest.mark.parametrize("spoil, why", [
    (lambda p: p.chmod(0o777), "has mode 0777: other users may use it"),
    (lambda p: p.chmod(0o750), "has mode 0750"),
    (lambda p: os.chown(p, 12345, 12345), "is owned by uid 12345"),
])
def test_a_folder_made_beforehand_that_is_not_private_is_refused(spoil, why: str, tmp: Path) -> None:  # type: ignore[no-untyped-def]
    folder = expected(tmp)
    folder.mkdir(mode=0o700)
    if "uid" in why and os.geteuid() != 0:
        pytest.skip("only root can give a folder to another user")
    spoil(folder)
    with pytest.raises(UnsafePath) as info:
        ssh.ensure_control_dir()
    assert why in info.value.message and str(folder) in info.value.message


def test_a_symlink_even_to_a_private_folder_is_refused(tmp: Path) -> None:
    real = tmp / "elsewhere"
    real.mkdir(mode=0o700)
    expected(tmp).symlink_to(real)
    with pytest.raises(UnsafePath, match="is a symlink"):
        ssh.ensure_control_dir()


def test_a_file_in_its_place_is_refused(tmp: Path) -> None:
    expected(tmp).write_text("")
    with pytest.raises(UnsafePath, match="is not a folder"):
        ssh.ensure_control_dir()


def test_a_private_runtime_folder_is_preferred(tmp: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    runtime = tmp / "run-user"
    runtime.mkdir(mode=0o700)
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(runtime))
    assert ssh.ensure_control_dir() == runtime / "robocore-ssh"
    runtime.chmod(0o755)  # not private: the temp folder instead
    assert ssh.control_dir() == expected(tmp)


def test_no_ssh_or_rsync_runs_through_a_folder_someone_else_may_use(tmp: Path) -> None:
    expected(tmp).mkdir(mode=0o777)
    expected(tmp).chmod(0o777)
    with pytest.raises(UnsafePath):
        ssh.run(HOST, ["true"])
    with pytest.raises(UnsafePath):
        rsync.run(HOST, ["rsync", "--version"])
    ssh.warm(HOST)  # warming says nothing and starts nothing
    assert not list(tmp.parent.glob("ran-*"))
    # negative control: with the folder fixed, the (fake) ssh and rsync do run
    expected(tmp).chmod(0o700)
    ssh.run(HOST, ["true"])
    rsync.run(HOST, ["rsync", "--version"])
    assert {p.name for p in tmp.parent.glob("ran-*")} == {"ran-ssh", "ran-rsync"}
