"""Symlinks a cloned repository carries where robocore writes or reads: nothing outside the project is written,
removed or read through them, and the refusal is one line naming the link, without a traceback.

The links are made as an attacker ships them: committed to a git repository, which is then cloned (git
recreates the symlinks). Outside the project lies a folder holding a canary file and files named as robocore's
own (``dev.yaml``, ``super_client.xml``, a record of written files naming the canary): a write through a link
would change them, a stale-file clean would remove them. Negative control: the same clone without the link
stages, and writes its files inside the project.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import built_project

from robocore.errors import UnsafePath
from robocore.files import WRITTEN_RECORD, make_folder, read_project_file, remove_file, remove_tree, write_atomic

ROBOT_YAML = """\
ros_distro: jazzy
hosts:
  - {name: dev, ip: 127.0.0.1}
components:
  - {name: talker, folder: components/talker, runs_on: dev}
"""

#: Link layouts: (path in the project, what it points to, relative to the project). ``OUT`` is the outside folder.
LAYOUTS = [
    (".robocore", "../outside"),
    (".robocore/compose", "../../outside"),
    (".robocore/dds", "../../outside"),
    (".robocore/compose/dev.yaml", "../../../outside/dev.yaml"),
    (".robocore/dds/super_client.xml", "../../../outside/super_client.xml"),
    (".robocore/build", "../../outside"),
    (".robocore/compose", "/tmp/../" + "x" * 8),  # a dangling absolute link: refused as well, nothing made
]


def git(cwd: Path, *args: str) -> None:
    subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@t", "-c", "init.defaultBranch=main", *args],
                   cwd=cwd, check=True, capture_output=True)


def outside_folder(parent: Path) -> tuple[Path, dict[str, bytes]]:
    outside = parent / "outside"
    outside.mkdir()
    files = {"canary": b"do not touch\n", "dev.yaml": b"mine\n", "super_client.xml": b"<mine/>\n",
             WRITTEN_RECORD: b"canary\ndev.yaml\n"}
    for name, data in files.items():
        (outside / name).write_bytes(data)
    return outside, files


def cloned(tmp_path: Path, links: list[tuple[str, str]]) -> Path:
    """A project committed with ``links`` to a git repository, then cloned next to the outside folder."""
    origin = tmp_path / "origin"
    built_project(origin, ROBOT_YAML, components=("talker",))
    for rel, target in links:
        link = origin / rel
        if link.is_dir() and not link.is_symlink():
            import shutil

            shutil.rmtree(link)
        elif os.path.lexists(link):
            link.unlink()
        link.parent.mkdir(parents=True, exist_ok=True)
        link.symlink_to(target)
    git(origin, "init", "-q")
    (origin / ".gitignore").write_text("/.robocore/build/\n/.robocore/*.json\n")
    git(origin, "add", "-A", "-f", "robot.yaml", "components", *[rel for rel, _ in links])
    git(origin, "commit", "-q", "-m", "hostile")
    clone = tmp_path / "clone"
    git(tmp_path, "clone", "-q", str(origin), str(clone))
    for rel, _ in links:
        assert (clone / rel).is_symlink(), rel
    return clone


def robocore(project: Path, *args: str, tmp: Path) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, DOCKER_HOST=f"unix://{tmp}/no-docker.sock")
    return subprocess.run([sys.executable, "-m", "robocore", "-p", str(project), *args], capture_output=True,
                          text=True, env=env, timeout=60, stdin=subprocess.DEVNULL)


def snapshot(folder: Path) -> dict[str, tuple[bytes, int]]:
    return {p.name: (p.read_bytes(), p.lstat().st_mtime_ns) for p in sorted(folder.iterdir())}


#: Every layout with stage (which writes compose files and DDS profiles); the folder layouts also with build and
#: sync, which check robocore's folders before they start.
CASES = [(link, target, ["stage", "--refresh"]) for link, target in LAYOUTS] + [
    (link, target, task) for link, target in LAYOUTS if not link.endswith((".yaml", ".xml"))
    for task in (["build"], ["sync"])]


@pytest.mark.parametrize("link, target, task", CASES, ids=[f"{' '.join(t)}:{a}->{b}" for a, b, t in CASES])
def test_a_link_where_robocore_writes_is_refused_and_nothing_outside_changes(
        tmp_path: Path, link: str, target: str, task: list[str]) -> None:
    outside, files = outside_folder(tmp_path)
    before = snapshot(outside)
    clone = cloned(tmp_path, [(link, target)])
    done = robocore(clone, *task, tmp=tmp_path)
    assert done.returncode == 2, done.stdout + done.stderr
    assert "Traceback" not in done.stderr
    first, *rest = done.stderr.splitlines()
    assert first.startswith("error: ") and "a symlink" in first and "where robocore writes" in first, first
    assert link.split("/")[-1] in first or ".robocore" in first
    assert all(line.startswith("hint: ") for line in rest)
    assert snapshot(outside) == before, "a file outside the project changed"
    assert {p.name for p in outside.iterdir()} == set(files)
    assert (clone / link).is_symlink()  # not removed either


def test_negative_control_the_same_clone_without_a_link_writes_inside(tmp_path: Path) -> None:
    outside, _ = outside_folder(tmp_path)
    before = snapshot(outside)
    clone = cloned(tmp_path, [])
    done = robocore(clone, "stage", "--refresh", tmp=tmp_path)
    assert done.returncode == 0, done.stderr
    assert (clone / ".robocore" / "compose" / "dev.yaml").read_text().startswith("# Generated by robocore")
    assert oct((clone / ".robocore" / "compose").stat().st_mode & 0o777) == oct(0o700)
    assert snapshot(outside) == before


@pytest.mark.parametrize("kind", ["link-out", "fifo", "folder", "device"])
def test_robot_yaml_that_leads_outside_or_is_not_a_file_is_one_line_at_once(tmp_path: Path, kind: str) -> None:
    outside, _ = outside_folder(tmp_path)
    (outside / "robot.yaml").write_text(ROBOT_YAML)
    project = tmp_path / "project"
    project.mkdir()
    robot = project / "robot.yaml"
    if kind == "link-out":
        robot.symlink_to(outside / "robot.yaml")
    elif kind == "fifo":
        os.mkfifo(robot)  # a reader that opened it normally would wait for a writer for ever
    elif kind == "folder":
        robot.mkdir()
    else:
        robot.symlink_to("/dev/zero")
    done = robocore(project, "validate", tmp=tmp_path)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    (line,) = done.stderr.splitlines()
    assert "robot.yaml" in line and ("outside the project" in line or "not a regular file" in line
                                     or "is not a file" in line), line


def test_package_xml_fifo_or_link_out_is_one_line(tmp_path: Path) -> None:
    from robocore.commands.support.workspace import package_manifests

    outside, _ = outside_folder(tmp_path)
    project = tmp_path / "project"
    built_project(project, ROBOT_YAML, components=("talker",))
    manifest = project / "components" / "talker" / "src" / "talker_pkg" / "package.xml"
    manifest.unlink()
    os.mkfifo(manifest)
    with pytest.raises(UnsafePath, match="not a regular file"):
        package_manifests(project / "components" / "talker", project)
    manifest.unlink()
    manifest.symlink_to(outside / "canary")
    with pytest.raises(UnsafePath, match="outside the project folder"):
        package_manifests(project / "components" / "talker", project)


def test_the_primitives_refuse_links_and_never_follow_them(tmp_path: Path) -> None:
    outside, files = outside_folder(tmp_path)
    root = tmp_path / "project"
    state = root / ".robocore"
    make_folder(state / "a")
    (state / "b").symlink_to(outside)
    (state / "a" / "f").symlink_to(outside / "canary")
    for call in (lambda: write_atomic(state / "b" / "x", "x"), lambda: write_atomic(state / "a" / "f", "x"),
                 lambda: make_folder(state / "b" / "sub"), lambda: remove_file(state / "b" / "canary"),
                 lambda: remove_file(state / "a" / "f"), lambda: remove_tree(state / "b"),
                 lambda: remove_tree(state / "b" / "sub")):
        with pytest.raises(UnsafePath, match="a symlink"):
            call()
    assert {p.name: p.read_bytes() for p in outside.iterdir()} == files
    write_atomic(state / "a" / "g", "ok", mode=0o600)
    assert oct((state / "a").stat().st_mode & 0o777) == oct(0o700)  # a folder of 0600 files is private
    assert read_project_file(state / "a" / "g", root) == b"ok"
    with pytest.raises(UnsafePath, match="outside the project"):
        read_project_file(state / "a" / "f", root)
