"""Builds on the robot (``builds_here``): which host builds what, the argv lists, the host's lock script and
the release of a host-built install tree (the scripts run here with sh and rsync, on local folders)."""

from __future__ import annotations

import os
import shlex
import subprocess
import time
from pathlib import Path, PurePosixPath

import pytest

from robocore.commands.support import host_build, state
from robocore.commands.sync import plan_host
from robocore.config.checks import check_robot
from robocore.config.model import Host, Robot
from robocore.errors import UsageError
from robocore.plan import colcon, naming
from robocore.plan import remote_build as plan
from robocore.plan.arches import INSTALL_ARCH_FILE
from robocore.plan.sync import LOCK_BUSY
from robocore.project import Project

BUILDER = Host(name="jetson", ip="10.0.0.7", user="pi", arch="arm64", builds_here=True)
PLAIN = Host(name="nuc", ip="10.0.0.5", user="root")


def _project(root: Path) -> Project:
    robot = Robot.model_validate({
        "ros_distro": "noetic",
        "base": {"kind": "debian"},
        "hosts": [{"name": "nuc", "ip": "10.0.0.5"},
                  {"name": "jetson", "ip": "10.0.0.7", "user": "pi", "arch": "arm64", "builds_here": True}],
        "components": [{"name": "talker", "runs_on": "jetson", "folder": "components/talker"},
                       {"name": "listener", "runs_on": "nuc", "folder": "components/listener"}],
    })
    return Project(root=root, robot=robot)


def test_only_a_remote_host_with_builds_here_builds_its_components() -> None:
    assert plan.builds_on_host(BUILDER)
    assert not plan.builds_on_host(PLAIN)
    local = Host(name="dev", ip="127.0.0.1", builds_here=True)
    assert not plan.builds_on_host(local)
    robot = Robot.model_validate({"ros_distro": "noetic", "hosts": [{"name": "dev", "ip": "127.0.0.1",
                                                                     "builds_here": True}]})
    assert [(key, text) for key, text in check_robot(robot, None) if "builds_here" in key] == [
        (("hosts", 0, "builds_here"),
         "builds_here: true only applies to a remote host (this machine builds its own components anyway)")]


def test_the_host_keeps_one_build_folder_per_component_mounted_where_a_local_build_mounts() -> None:
    where = plan.host_build(BUILDER, "talker")
    assert where.root == PurePosixPath("/home/pi/robocore/talker")
    assert where.install == PurePosixPath("/home/pi/robocore/talker/work/install")
    mounts = where.mounts(ccache=True)
    assert mounts == {
        "/home/pi/robocore/talker/work/ws": naming.CONTAINER_WS,
        "/home/pi/robocore/talker/work/build": colcon.CONTAINER_BUILD,
        "/home/pi/robocore/talker/work/install": naming.CONTAINER_INSTALL,
        "/home/pi/robocore/talker/work/log": colcon.CONTAINER_LOG,
        "/home/pi/robocore/talker/work/ccache": colcon.CONTAINER_CCACHE,
    }
    assert colcon.CONTAINER_CCACHE not in where.mounts(ccache=False).values()


def test_the_workspace_goes_with_rsync_deltas_without_outputs_and_operands_after_dashes(tmp_path: Path) -> None:
    ws = tmp_path / "components" / "talker"
    argv = plan.workspace_rsync_argv(ws, plan.host_build(BUILDER, "talker"), BUILDER, "ssh -p 22",
                                     skip_dirs=["node_modules"])
    assert argv[0] == "rsync" and {"-a", "-s", "--delete", "--stats", "--copy-unsafe-links"} <= set(argv)
    assert {"--exclude=/build/", "--exclude=/install/", "--exclude=/log/", "--exclude=.*",
            "--exclude=node_modules/"} <= set(argv)
    assert argv[argv.index("-e") + 1] == "ssh -p 22"
    assert argv[-3:] == ["--", f"{ws}/", "pi@10.0.0.7:/home/pi/robocore/talker/work/ws/"]
    back = plan.fetch_install_argv(plan.host_build(BUILDER, "talker"), BUILDER, "ssh", tmp_path / "install")
    assert back[-3:] == ["--", "pi@10.0.0.7:/home/pi/robocore/talker/work/install/", f"{tmp_path}/install/"]


def test_the_release_copy_runs_on_the_host_and_links_against_current() -> None:
    argv = plan.release_install_argv(plan.host_build(BUILDER, "talker"))
    assert argv == ["sh", "-c", plan.RELEASE_SCRIPT, "sh", "/home/pi/robocore/talker/current/install/",
                    "/home/pi/robocore/talker/work/install/", "/home/pi/robocore/talker/staging/install/"]


def test_the_release_copy_never_changes_an_earlier_release(tmp_path: Path) -> None:
    """Run on local folders as the host runs it: an unchanged file becomes a hard link to the current release,
    a rebuilt one a new file; the current release keeps its content."""
    host = Host(name="h", ip="10.0.0.9", mount_root=str(tmp_path))
    where = plan.host_build(host, "talker")
    install = Path(str(where.install))
    (install / "lib").mkdir(parents=True)
    (install / "lib" / "talker").write_text("v1")
    (install / "setup.sh").write_text("same")
    first = Path(str(where.root)) / "releases" / "r1"
    subprocess.run(plan.release_install_argv(where), check=True, capture_output=True)
    first.parent.mkdir()
    (Path(str(where.root)) / "staging").rename(first)
    (Path(str(where.root)) / "current").symlink_to("releases/r1")
    (install / "lib" / "talker").write_text("v2")  # the host rebuilt the talker in place, a second later
    os.utime(install / "lib" / "talker", (time.time() + 2, time.time() + 2))
    out = subprocess.run(plan.release_install_argv(where), check=True, capture_output=True, text=True).stdout
    staged = Path(str(where.root)) / "staging" / "install"
    assert (staged / "lib" / "talker").read_text() == "v2"
    assert (first / "install" / "lib" / "talker").read_text() == "v1"
    assert (staged / "setup.sh").stat().st_ino == (first / "install" / "setup.sh").stat().st_ino
    assert "Number of regular files transferred: 1" in out


def test_the_lock_script_takes_the_sync_lock_makes_the_folders_and_says_who_builds(tmp_path: Path) -> None:
    # built without validation (robot.yaml refuses such a folder): the script takes it as data all the same
    host = Host.model_construct(name="h", ip="10.0.0.9", mount_root=str(tmp_path / "root; touch pwned"))
    where = plan.host_build(host, "talker")
    argv = plan.lock_argv(host, "alice@dev", where)
    assert argv[:3] == ["sh", "-c", plan.LOCK_SCRIPT]
    holder = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=tmp_path)
    assert holder.stdin is not None and holder.stdout is not None
    lines = [holder.stdout.readline().strip() for _ in range(3)]
    assert lines[2] == plan.LOCKED
    assert plan.parse_ids(lines[:2]) == f"{subprocess.check_output(['id', '-u'], text=True).strip()}:" \
                                        f"{subprocess.check_output(['id', '-g'], text=True).strip()}"
    assert all(Path(str(where.work / sub)).is_dir() for sub in ("ws", "build", "install", "log", "ccache"))
    # a sync (or another build) of this host now finds the lock taken
    second = subprocess.run(plan.lock_argv(host, "bob@dev", where), capture_output=True, text=True,
                            stdin=subprocess.DEVNULL)
    assert second.returncode == LOCK_BUSY and "alice@dev" in second.stderr
    holder.stdin.write(plan.finish_line("arm64") + "\n")  # a successful build: its arch goes into the tree
    holder.stdin.flush()
    assert holder.stdout.readline().strip() == plan.DONE
    assert holder.wait(timeout=10) == 0
    assert Path(str(where.install / INSTALL_ARCH_FILE)).read_text() == "arm64\n"
    assert plan.finish_line(None) == "done"
    with pytest.raises(ValueError):
        plan.finish_line("arm64; rm -rf /")
    assert not (tmp_path / "pwned").exists() and (tmp_path / "root; touch pwned" / ".robocore-sync.lock").is_file()
    with pytest.raises(ValueError):
        plan.parse_ids(["uid=; rm", "gid=0"])


def test_the_host_plan_says_what_changed_since_the_last_build_there(tmp_path: Path) -> None:
    project = _project(tmp_path)
    comp = project.component("talker")
    jetson = project.host("jetson")
    first = host_build.plan_host_build(project, comp, jetson, "img:latest", "sha256:1", {"demo_talker": "a"})
    assert first.changed is None and first.reason == "on host jetson: first build"
    assert "--packages-above" not in first.argv
    host_build.record_host_build(project, first)
    same = host_build.plan_host_build(project, comp, jetson, "img:latest", "sha256:1", {"demo_talker": "a"})
    assert same.changed == []
    edited = host_build.plan_host_build(project, comp, jetson, "img:latest", "sha256:1",
                                        {"demo_talker": "b"}, ccache=True)
    assert edited.changed == ["demo_talker"]
    assert edited.argv[edited.argv.index("--packages-above") + 1] == "demo_talker"
    env = host_build.container_env(edited)
    assert env["CMAKE_CXX_COMPILER_LAUNCHER"] == "ccache" and "MAKEFLAGS" not in env  # the host's own cores
    new_image = host_build.plan_host_build(project, comp, jetson, "img:latest", "sha256:2", {"demo_talker": "a"})
    assert new_image.changed is None and new_image.reason == "on host jetson: image changed"
    moved = Host(name="other", ip="10.0.0.8", builds_here=True)
    elsewhere = host_build.plan_host_build(project, comp, moved, "img:latest", "sha256:1", {"demo_talker": "a"})
    assert elsewhere.changed is None and elsewhere.reason == "on host other: last built on host jetson"


def test_sync_releases_a_host_built_tree_from_the_host_or_asks_for_a_build(tmp_path: Path) -> None:
    project = _project(tmp_path)
    jetson = project.host("jetson")
    project.dds_dir.mkdir(parents=True)
    project.compose_file("jetson").parent.mkdir(parents=True, exist_ok=True)
    project.compose_file("jetson").write_text("services: {}\n")
    with pytest.raises(UsageError, match="not built on host jetson yet"):
        plan_host(project, jetson)
    build = host_build.plan_host_build(project, project.component("talker"), jetson, "img", "sha256:1", {"p": "a"})
    host_build.record_host_build(project, build)
    [item] = plan_host(project, jetson)
    assert item.install_on_host == PurePosixPath("/home/pi/robocore/talker/work/install")
    assert "install" not in {s.name for s in item.sources}  # nothing of it is sent from this machine
    recorded = state.read_build_state(project.host_build_state_file("talker"))
    assert item.host_build_id == recorded["build"]


def test_dry_run_lists_every_step_with_values_quoted(tmp_path: Path) -> None:
    project = _project(tmp_path)
    build = host_build.plan_host_build(project, project.component("talker"), project.host("jetson"),
                                       "robocore-talker:latest", None, {"demo_talker": "a"})
    steps = host_build.dry_run_steps(build, tmp_path / "components" / "talker")
    assert steps[0] == "deliver robocore-talker:latest to host jetson"
    assert steps[1] == "hold the lock /home/pi/robocore/.robocore-sync.lock on jetson (as sync does) while:"
    assert shlex.split(steps[2])[0] == "rsync"
    assert steps[3].endswith(shlex.join(build.argv))
