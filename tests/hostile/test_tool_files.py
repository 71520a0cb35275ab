"""Files robocore writes and copies: modes (umask, 0600 compose files), dry runs that write nothing, and
symlinks or ``../`` paths that would carry files from outside the project into an image or onto a robot."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from robocore import files
from robocore.commands import build, stage
from robocore.commands import sync as sync_command
from robocore.commands.support.composefiles import write_compose_files
from robocore.commands.support.context import Options
from robocore.errors import UnsafePath
from robocore.project import Project

ROBOT_YAML = """\
ros_distro: jazzy
base: {{kind: official}}
hosts:
  - {{name: pi, ip: "10.0.0.7", user: pi}}
  - {{name: dev, ip: 127.0.0.1, user: me}}
components:
  - name: talker
    folder: components/talker
    runs_on: pi
    environment: {{API_TOKEN: secret-value}}
    volumes: [{volume}]
  - {{name: listener, folder: components/listener, runs_on: dev}}
"""


def make(tmp_path: Path, volume: str = '"./config:/config:ro"') -> Project:
    root = tmp_path / "robot"
    for folder in ("components/talker/src/pkg", "components/listener/src/lpkg", "config"):
        (root / folder).mkdir(parents=True)
    (root / "components/talker/src/pkg/package.xml").write_text("<package><name>pkg</name></package>")
    (root / "components/listener/src/lpkg/package.xml").write_text("<package><name>lpkg</name></package>")
    (root / "config" / "params.yaml").write_text("rate: 10\n")
    (root / "robot.yaml").write_text(ROBOT_YAML.format(volume=volume))
    return Project.load(root)


def mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


# --------------------------------------------------------------------------------------------- modes


def test_the_umask_is_read_without_changing_it() -> None:
    old = os.umask(0o027)
    try:
        assert files.read_umask() == 0o027
        assert os.umask(0o027) == 0o027  # still what it was
    finally:
        os.umask(old)


@pytest.mark.parametrize("umask, expected", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o644), (0o000, 0o644)])
def test_write_atomic_gives_new_files_outside_the_state_folder_the_umasks_mode(
        umask: int, expected: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(files, "UMASK", umask)

    def no_umask(_: int) -> int:
        raise AssertionError("write_atomic must not touch the process umask (threads share it)")

    monkeypatch.setattr(os, "umask", no_umask)
    path = tmp_path / "sub" / "f.txt"
    assert files.write_atomic(path, "x")
    assert mode(path) == expected
    assert files.write_atomic(path, b"y", mode=0o600) and mode(path) == 0o600  # an explicit mode wins


def test_an_explicit_mode_narrows_an_unchanged_file(tmp_path: Path) -> None:
    path = tmp_path / "f"
    path.write_text("same")
    path.chmod(0o644)
    assert not files.write_atomic(path, "same", mode=0o600)  # not rewritten...
    assert mode(path) == 0o600  # ...but narrowed


def test_compose_files_holding_environment_values_are_private(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(files, "UMASK", 0o002)  # a permissive umask
    project = make(tmp_path)
    old = project.compose_file("pi")
    old.parent.mkdir(parents=True)
    paths = write_compose_files(project)
    assert {p.name for p in paths} == {"dev.yaml", "pi.yaml"}
    assert "secret-value" in project.compose_file("pi").read_text()
    assert all(mode(p) == 0o600 for p in paths)
    assert mode(project.state_dir / "dds" / "super_client.xml") == 0o644  # read in containers: SHARED, not 0664
    project.compose_file("pi").chmod(0o644)  # written by an older robocore
    write_compose_files(project)
    assert mode(project.compose_file("pi")) == 0o600


# --------------------------------------------------------------------------------------------- sync --dry-run


def tree(root: Path) -> list[tuple[str, int]]:
    return sorted((str(p.relative_to(root)), p.lstat().st_mtime_ns) for p in root.rglob("*"))


def test_sync_dry_run_writes_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path / "tmp"))  # where ssh's control folder would go
    (tmp_path / "tmp").mkdir()
    monkeypatch.delenv("XDG_RUNTIME_DIR", raising=False)
    loaded = make(tmp_path)
    # an IPv6 address (robot.yaml's checks may refuse one for DDS; this layer must still get it right)
    hosts = [h.model_copy(update={"ip": "fe80::1"}) if h.name == "pi" else h for h in loaded.robot.hosts]
    project = Project(root=loaded.root, robot=loaded.robot.model_copy(update={"hosts": hosts}))
    write_compose_files(project)
    (project.build_dir("talker") / "install" / "share").mkdir(parents=True)
    before = tree(project.root)
    monkeypatch.setattr(Options, "load", lambda self: project)
    sync_command.sync(Options(project_dir=project.root, dry_run=True), host=None)
    out = capsys.readouterr().out
    assert "rsync -a -R -s" in out and "'pi@[fe80::1]:" in out and "-- " in out
    assert tree(project.root) == before, "a dry run created or changed files"
    assert list((tmp_path / "tmp").iterdir()) == [], "a dry run created ssh's control folder"
    # negative control: planning for real makes the folder of links to the read-only volumes
    sync_command.plan_host(project, project.host("pi"))
    assert tree(project.root) != before


# --------------------------------------------------------------------------------------------- symlinks


def test_a_workspace_symlink_leading_out_of_the_project_is_refused(tmp_path: Path) -> None:
    project = make(tmp_path)
    secret = tmp_path / "outside" / "id_rsa"
    secret.parent.mkdir()
    secret.write_text("KEY")
    link = project.root / "components/talker/src/pkg/key"
    link.symlink_to(secret)
    talker = project.robot.component("talker")
    with pytest.raises(UnsafePath) as info:
        stage.plan_component(project, talker, stage.BaseRef("b:latest", "amd64", "x"))
    assert info.value.message.startswith("components/talker/src/pkg/key: a symlink to ")
    assert str(secret) in info.value.message and "outside the project" in info.value.message
    with pytest.raises(UnsafePath):
        build.plan_build(project, talker, "sha256:x")
    link.unlink()
    link.symlink_to("../../../listener/src/lpkg/package.xml")  # inside the project: fine
    stage.plan_component(project, talker, stage.BaseRef("b:latest", "amd64", "x"))
    build.plan_build(project, talker, "sha256:x")


def test_links_in_folders_robocore_never_reads_are_left_alone(tmp_path: Path) -> None:
    project = make(tmp_path)
    ws = project.root / "components/talker"
    for folder in (".git/objects", "build", "src/pkg/__pycache__"):
        (ws / folder).mkdir(parents=True, exist_ok=True)
        (ws / folder / "link").symlink_to("/etc/hostname")
    build.plan_build(project, project.robot.component("talker"), "sha256:x")
    (ws / "src" / "link").symlink_to("/etc/hostname")  # negative control: in the sources it counts
    with pytest.raises(UnsafePath, match=r"^components/talker/src/link: "):
        build.plan_build(project, project.robot.component("talker"), "sha256:x")


def test_a_workspace_folder_that_is_itself_a_link_out_of_the_project_is_refused(tmp_path: Path) -> None:
    project = make(tmp_path)
    home = tmp_path / "home"
    (home / "src").mkdir(parents=True)
    ws = project.root / "components/talker"
    os.rename(ws, tmp_path / "moved")
    ws.symlink_to(home)
    with pytest.raises(UnsafePath, match=r"^components/talker: a symlink to"):
        build.plan_build(project, project.robot.component("talker"), "sha256:x")


def test_a_volume_linked_out_of_the_project_is_sent_only_with_the_components_opt_in(tmp_path: Path) -> None:
    project = make(tmp_path, '"./linked:/l:ro"')
    (tmp_path / "outside").mkdir()
    (project.root / "linked").symlink_to(tmp_path / "outside")
    write_compose_files(project)
    (project.build_dir("talker") / "install").mkdir(parents=True)
    with pytest.raises(UnsafePath, match=r"volumes\[0\]: linked leads to .*outside, outside the project folder"):
        sync_command.plan_host(project, project.host("pi"), dry_run=True)
    talker = project.robot.component("talker").model_copy(update={"allow_outside_project": True})
    others = [c for c in project.robot.components if c.name != "talker"]
    opted = Project(root=project.root, robot=project.robot.model_copy(update={"components": [talker, *others]}))
    items = sync_command.plan_host(opted, opted.host("pi"), dry_run=True)
    assert [s.name for s in items[0].sources][-1] == "files"


def test_sync_refuses_install_tree_links_and_volumes_that_leave_the_project(tmp_path: Path) -> None:
    project = make(tmp_path)
    write_compose_files(project)
    install = project.build_dir("talker") / "install"
    (install / "share").mkdir(parents=True)
    (install / "share" / "key").symlink_to(tmp_path.parent / "anything")
    with pytest.raises(UnsafePath, match=r"install/share/key: a symlink to .*sent to host pi"):
        sync_command.plan_host(project, project.host("pi"), dry_run=True)
    (install / "share" / "key").unlink()
    sync_command.plan_host(project, project.host("pi"), dry_run=True)  # fine again
    config = project.root / "config"
    (config / "params.yaml").unlink()
    (config / "params.yaml").symlink_to("/etc/hostname")
    with pytest.raises(UnsafePath, match=r"config/params\.yaml: a symlink to '/etc/hostname'"):
        sync_command.plan_host(project, project.host("pi"), dry_run=True)


@pytest.mark.parametrize("volume", ["../outside:/o:ro", "./linked:/l:ro"])
def test_a_read_only_volume_outside_the_project_is_not_sent(volume: str, tmp_path: Path) -> None:
    """robot.yaml's checks refuse ``../``; this layer refuses it too (the model built without them)."""
    loaded = make(tmp_path)
    talker = loaded.robot.component("talker").model_copy(update={"volumes": [volume]})
    others = [c for c in loaded.robot.components if c.name != "talker"]
    project = Project(root=loaded.root, robot=loaded.robot.model_copy(update={"components": [talker, *others]}))
    (tmp_path / "outside").mkdir()
    (project.root / "linked").symlink_to(tmp_path / "outside")
    write_compose_files(project)
    (project.build_dir("talker") / "install").mkdir(parents=True)
    with pytest.raises(UnsafePath, match=r"volumes\[0\]: .* (is outside|leads to .*, outside) the project folder"):
        sync_command.plan_host(project, project.host("pi"), dry_run=True)
