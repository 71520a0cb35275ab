"""sync to two simulated robot hosts over ssh: only changed bytes move, atomically, per host.

The hosts are Docker-in-Docker containers running sshd (robot_host/). The install trees here
are synthetic (a copy of a real Python package plus a generated module): sync does not care
what it copies, and this keeps the suite free of image builds. The full build -> sync -> run
path is in test_multihost.py.
"""

from __future__ import annotations

import hashlib
import json
import os
import random
import shlex
import shutil
import signal
import subprocess
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
from deploy_helpers import wait_for

if TYPE_CHECKING:
    from conftest import Restorer, RobocoreCli
    from robot_host.hosts import RobotFleet

pytestmark = pytest.mark.docker

PROJECT_YAML = """\
ros_distro: jazzy
base:
  kind: wheels
hosts:
{hosts}components:
  - name: talker
    runs_on: robot-a
    folder: components/talker
    volumes: ["./config:/robocore-config:ro", "./data:/data"]
  - name: listener
    runs_on: robot-b
    folder: components/listener
"""


@pytest.fixture(scope="module")
def project(fleet: RobotFleet, tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("sync") / "syncbot"
    root.mkdir()
    (root / "robot.yaml").write_text(PROJECT_YAML.format(hosts=fleet.host_yaml(["robot-a", "robot-b"])))
    import rich

    for comp in ("talker", "listener"):
        (root / "components" / comp / "src").mkdir(parents=True)
        install = root / ".robocore" / "build" / comp / "install"
        # A real-looking tree: a copied package (hundreds of files) and a generated module.
        shutil.copytree(Path(rich.__file__).parent, install / f"demo_{comp}" / "lib" / "rich")
        module = install / f"demo_{comp}" / "lib" / f"{comp}.py"
        module.write_text("".join(f"LINE_{i} = {i * 7919 % 100003}\n" for i in range(20000)))
    (root / "config" / "maps").mkdir(parents=True)
    (root / "config" / "maps" / "params.yaml").write_text("rate: 2\n")
    (root / "data").mkdir()  # writable: stays on the robot, never copied
    (root / "data" / "local-only.txt").write_text("x\n")
    (root / ".robocore" / "dds").mkdir(parents=True)
    (root / ".robocore" / "dds" / "super_client.xml").write_text("<profiles/>\n")
    (root / ".robocore" / "compose").mkdir()
    for host in ("robot-a", "robot-b"):
        (root / ".robocore" / "compose" / f"{host}.yaml").write_text(f"# {host}\nservices: {{}}\n")
    return root


SyncJson = Callable[..., dict[str, dict[str, Any]]]


@pytest.fixture(scope="module")
def sync_json(run_robocore: RobocoreCli) -> SyncJson:
    """``sync_json(project, *args)``: ``robocore sync --json ARGS`` (must succeed), its results by host."""

    def sync(project: Path, *args: str) -> dict[str, dict[str, Any]]:
        data = json.loads(run_robocore(project, "sync", "--json", *args).stdout)
        return {row["host"]: row for row in data["results"]}

    return sync


def tree_digests(root: Path) -> dict[str, str]:
    out = {}
    for path in sorted(root.rglob("*")):
        if path.is_file():
            out[str(path.relative_to(root))] = hashlib.sha256(path.read_bytes()).hexdigest()
    return out


def remote_digests(fleet: RobotFleet, index: int, folder: str) -> dict[str, str]:
    text = fleet.hosts[index].ssh(fleet, "sh", "-c", 'cd "$1" && find . -type f -exec sha256sum {} +', "sh", folder)
    out = {}
    for line in text.splitlines():
        digest, name = line.split(maxsplit=1)
        out[name.removeprefix("./")] = digest
    return out


def current_target(fleet: RobotFleet, index: int, comp: str) -> str:
    return fleet.hosts[index].ssh(fleet, "readlink", f"/root/robocore/{comp}/current").strip()


def test_dry_run_prints_commands_and_copies_nothing(fleet: RobotFleet, project: Path,
                                                    run_robocore: RobocoreCli) -> None:
    proc = run_robocore(project, "sync", "--dry-run")
    assert "rsync -a -R -s --delete" in proc.stdout
    assert "--link-dest=/root/robocore/talker/current/" in proc.stdout
    assert f"root@{fleet.hosts[1].ip}:/root/robocore/listener/staging/" in proc.stdout
    listing = fleet.hosts[0].ssh(fleet, "ls", "-a", "/root")
    assert "robocore" not in listing.split()


def test_sync_moves_trees_then_only_what_changed(fleet: RobotFleet, project: Path, sync_json: SyncJson) -> None:
    talker_install = project / ".robocore" / "build" / "talker" / "install"
    tree_bytes = sum(p.stat().st_size for p in talker_install.rglob("*") if p.is_file())

    first = sync_json(project)
    assert first["robot-a"]["changed"] and first["robot-b"]["changed"]
    assert first["robot-a"]["sent"] > 0.5 * tree_bytes, "the first sync must carry the whole tree"
    assert remote_digests(fleet, 0, "/root/robocore/talker/current/install") == tree_digests(talker_install)
    listener_install = project / ".robocore" / "build" / "listener" / "install"
    assert remote_digests(fleet, 1, "/root/robocore/listener/current/install") == tree_digests(listener_install)
    # each host got its own compose file, also as compose.yaml; components are not mixed up
    assert "# robot-b" in fleet.hosts[1].ssh(fleet, "cat", "/root/robocore/listener/current/compose.yaml")
    assert "talker" not in fleet.hosts[1].ssh(fleet, "ls", "/root/robocore")

    second = sync_json(project)
    for host in ("robot-a", "robot-b"):
        assert not second[host]["changed"]
        assert second[host]["release"] == first[host]["release"]
        assert int(second[host]["sent"]) < 10_000, second[host]  # file list only
    assert current_target(fleet, 0, "talker") == f"releases/{first['robot-a']['release']}"

    module = talker_install / "demo_talker" / "lib" / "talker.py"
    module.write_text(module.read_text().replace("LINE_10000 = ", "LINE_10000 = 1 + ", 1))
    third = sync_json(project)
    assert third["robot-a"]["changed"] and third["robot-a"]["release"] != first["robot-a"]["release"]
    assert int(third["robot-a"]["sent"]) < 50_000, third["robot-a"]
    assert not third["robot-b"]["changed"]
    remote = fleet.hosts[0].ssh(fleet, "grep", "-c", "LINE_10000 = 1 + ", "/root/robocore/talker/current/install/"
                                "demo_talker/lib/talker.py")
    assert remote.strip() == "1"
    # negative control: the byte count is real: 1 MB of incompressible data is reported as such
    (talker_install / "noise.bin").write_bytes(random.randbytes(1_000_000))
    fourth = sync_json(project, "--host", "robot-a")
    assert int(fourth["robot-a"]["sent"]) > 1_000_000
    assert "robot-b" not in fourth
    # unchanged files of the new release are hard links into the previous one (no second copy)
    links = fleet.hosts[0].ssh(fleet, "stat", "-c", "%h", "/root/robocore/talker/current/install/demo_talker/lib/"
                               "rich/console.py")
    assert int(links.strip()) >= 2
    # a deleted file disappears from the next release
    (talker_install / "noise.bin").unlink()
    sync_json(project, "--host", "robot-a")
    assert "noise.bin" not in fleet.hosts[0].ssh(fleet, "ls", "/root/robocore/talker/current/install")
    releases = fleet.hosts[0].ssh(fleet, "ls", "/root/robocore/talker/releases").split()
    assert len(releases) == 3, releases  # older ones pruned


def test_read_only_project_volumes_travel_with_the_release(fleet: RobotFleet, project: Path, sync_json: SyncJson,
                                                           run_robocore: RobocoreCli, restore: Restorer) -> None:
    """./config:...:ro is copied into each release (where run mounts it from); ./data (writable) is not."""
    sync_json(project)
    files = "/root/robocore/talker/current/files"
    assert fleet.hosts[0].ssh(fleet, "cat", f"{files}/config/maps/params.yaml") == "rate: 2\n"
    assert "data" not in fleet.hosts[0].ssh(fleet, "ls", files).split()
    assert "local-only.txt" not in fleet.hosts[0].ssh(fleet, "find", "/root/robocore")
    params = project / "config" / "maps" / "params.yaml"
    params.write_text("rate: 5\n")
    again = sync_json(project)
    assert again["robot-a"]["changed"], "an edited project file must make a new release"
    assert fleet.hosts[0].ssh(fleet, "cat", f"{files}/config/maps/params.yaml") == "rate: 5\n"
    config = project / "config"
    restore.keep(config, project / "config.moved")
    config.rename(project / "config.moved")
    proc = run_robocore(project, "sync", check=False)
    assert proc.returncode != 0 and "Traceback" not in proc.stderr
    assert f"component talker: volumes[0]: {config} does not exist" in proc.stderr


def test_interrupted_sync_leaves_current_on_a_complete_release(fleet: RobotFleet, project: Path, sync_json: SyncJson,
                                                              run_robocore: RobocoreCli, restore: Restorer) -> None:
    talker_install = project / ".robocore" / "build" / "talker" / "install"
    sync_json(project, "--host", "robot-a")
    before = current_target(fleet, 0, "talker")
    before_tree = remote_digests(fleet, 0, "/root/robocore/talker/current/install")
    big = talker_install / "big.bin"
    restore.keep(big)  # removed even when the test fails: later syncs would carry it
    with big.open("wb") as handle:
        for _ in range(40):
            handle.write(os.urandom(8 << 20))  # 320 MB: takes long enough to interrupt
    module = talker_install / "demo_talker" / "lib" / "talker.py"
    module.write_text(module.read_text().replace("LINE_5 = ", "LINE_5 = 2 + ", 1))
    proc = run_robocore.start(project, "sync", "--host", "robot-a", stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)

    def copying_big() -> bool:  # rsync is writing its temp file: interrupt now
        staging = "ls -a /root/robocore/talker/staging/install 2>/dev/null"
        return ".big.bin." in fleet.hosts[0].ssh(fleet, "sh", "-c", staging, check=False)

    assert wait_for(copying_big, 60, interval=0.05), "rsync never started copying big.bin"
    os.killpg(proc.pid, signal.SIGKILL)  # the CLI and its rsync and ssh
    proc.wait()
    # current still names the previous release, whose files are all intact
    assert current_target(fleet, 0, "talker") == before
    assert remote_digests(fleet, 0, "/root/robocore/talker/current/install") == before_tree
    assert "big.bin" not in before_tree
    # negative control: the kill really happened midway (a partial staging copy is left behind)
    staged = fleet.hosts[0].ssh(fleet, "ls", "-a", "/root/robocore/talker/staging/install")
    assert "big.bin" not in staged.split()

    after = sync_json(project, "--host", "robot-a")
    assert after["robot-a"]["changed"]
    assert current_target(fleet, 0, "talker") == f"releases/{after['robot-a']['release']}"
    assert remote_digests(fleet, 0, "/root/robocore/talker/current/install") == tree_digests(talker_install)
    assert "staging" not in fleet.hosts[0].ssh(fleet, "ls", "/root/robocore/talker").split()
    big.unlink()
    sync_json(project, "--host", "robot-a")


def test_a_second_sync_to_a_host_being_synced_is_refused_and_names_the_first(
        fleet: RobotFleet, project: Path, sync_json: SyncJson, run_robocore: RobocoreCli,
        background: Callable[..., Any]) -> None:
    """Another developer's sync holds robot-a's lock: this sync must not touch robot-a (its staging
    would mix two trees), must say who holds it, and must still sync robot-b. Negative control: once
    the lock is free, the same sync goes through."""
    from robocore.plan import sync as plan

    module = project / ".robocore" / "build" / "talker" / "install" / "demo_talker" / "lib" / "talker.py"
    module.write_text(module.read_text() + "LOCKED_EDIT = 1\n")
    before = current_target(fleet, 0, "talker")
    holder = background(
        ["ssh", "-F", str(fleet.ssh_config), f"root@{fleet.hosts[0].ip}", "--",
         shlex.join(plan.session_argv("/root/robocore", "alice@her-laptop (pid 4242)", []))],
        stdin=subprocess.PIPE, stderr=None)
    assert holder.stdout is not None and holder.stdout.readline().strip() == plan.LOCKED
    proc = run_robocore(project, "sync", "--json", check=False)
    assert proc.returncode != 0
    assert "host robot-a: another sync to this host is in progress: alice@her-laptop (pid 4242)" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert current_target(fleet, 0, "talker") == before
    assert "staging" not in fleet.hosts[0].ssh(fleet, "ls", "/root/robocore/talker").split()
    assert {row["host"] for row in json.loads(proc.stdout)["results"]} == {"robot-b"}
    assert holder.stdin is not None
    holder.stdin.close()  # alice's sync ends: the lock is free
    holder.wait(timeout=30)
    after = sync_json(project)
    assert after["robot-a"]["changed"] and current_target(fleet, 0, "talker") != before
    remote = "/root/robocore/talker/current/install/demo_talker/lib/talker.py"
    assert "LOCKED_EDIT = 1" in fleet.hosts[0].ssh(fleet, "cat", remote)


def test_stopped_host_is_named_fast_and_the_other_host_still_syncs(fleet: RobotFleet, project: Path,
                                                                   run_robocore: RobocoreCli) -> None:
    # runs last in this module: it stops robot-b
    module = project / ".robocore" / "build" / "talker" / "install" / "demo_talker" / "lib" / "talker.py"
    module.write_text(module.read_text().replace("LINE_7 = ", "LINE_7 = 3 + ", 1))
    before = current_target(fleet, 0, "talker")
    fleet.stop(1)
    start = time.monotonic()
    proc = run_robocore(project, "sync", check=False)
    elapsed = time.monotonic() - start
    assert proc.returncode != 0
    assert "robot-b" in proc.stderr and "succeeded: robot-a" in proc.stderr, proc.stderr
    assert elapsed < 15, f"sync took {elapsed:.1f} s with one host down"
    assert current_target(fleet, 0, "talker") != before  # robot-a got its new release anyway

    start = time.monotonic()
    doctor = run_robocore(project, "doctor", check=False)
    assert time.monotonic() - start < 10
    assert doctor.returncode != 0
    assert "error: robot-b: " in doctor.stderr and "error: robot-a" not in doctor.stderr, doctor.stderr
