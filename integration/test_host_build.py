"""A robot host that builds its own components (``builds_here: true``): the noetic project on the debian base.

Two Docker-in-Docker hosts over ssh: robot-a (arm64: its daemon runs arm64 containers through the kernel's qemu
registration, as a Jetson's daemon runs them natively) builds its own components and runs the roscpp talker;
robot-b (amd64) runs the ROS master and the rospy listener, built on this machine. The project has the name of
integration/test_arm64.py's, so that the per-arch bases and staged images that module made are reused (content
hashes: nothing is rebuilt when they are current).

- ``build`` compiles the talker on robot-a: its build container is created on robot-a's daemon and never on
  this machine's (Docker's events of both daemons, negative control), the install tree is on robot-a (an
  ELF of robot-a's arch, the arch recorded) and not on this machine; a second ``build`` is up to date without a
  container anywhere;
- ``sync`` releases that tree from robot-a's own build folder (this machine has none to send), ``run`` starts
  both hosts, robot-b's listener hears robot-a's talker through the master; robot-b alone hears nothing
  (negative control);
- a one-line edit of the talker is rebuilt on robot-a incrementally (only demo_talker; its build folder
  persists there), released by ``sync`` and heard;
- ``release`` to a local registry pushes one manifest list per image naming each arch in use; ``run --tag``
  has each host pull that one reference and run its own arch (``uname -m``, the image's Architecture); a
  pull of an arch the list does not name fails (negative control).
"""

from __future__ import annotations

import contextlib
import json
import shutil
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
import yaml
from arm64_project import NAME, init_project
from deploy_helpers import HEARD, log_lines, remove_project_containers, wait_for
from local_registry import manifest, serve_registry

if TYPE_CHECKING:
    from conftest import RobocoreCli
    from robot_host.hosts import RobotFleet

pytestmark = pytest.mark.docker

TALKER_TEXT = "hello from talker #"
#: The arch of each host: robot-a builds for arm64 on its own (emulating) daemon, robot-b runs amd64.
ARCHES = {"robot-a": "arm64", "robot-b": "amd64"}
#: ELF e_machine of each arch (bytes 18-19 of the header, little-endian).
ELF_MACHINE = {"amd64": "62 0", "arm64": "183 0"}
MACHINES = {"amd64": "x86_64", "arm64": "aarch64"}


@pytest.fixture(scope="module")
def project(robot_fleets: Callable[..., RobotFleet], run_robocore: RobocoreCli,
            docker_client: Any, arm64_images: None) -> Iterator[tuple[RobotFleet, Path]]:
    """The template's noetic project, staged: the talker on robot-a (builds_here), master and listener on robot-b."""
    fleet = robot_fleets(2)
    parent = Path(tempfile.mkdtemp(prefix="robocore-it-"))
    root = parent / NAME
    hosts = [{"name": "robot-a", "ip": fleet.hosts[0].ip, "user": "root", "arch": ARCHES["robot-a"],
              "builds_here": True},
             {"name": "robot-b", "ip": fleet.hosts[1].ip, "user": "root", "arch": ARCHES["robot-b"]}]
    init_project(root, hosts, talker_host="robot-a", server_host="robot-b")
    for step in ("prepare-base", "stage"):
        run_robocore(root, step, "--quiet")
    yield fleet, root
    remove_project_containers(docker_client, NAME)
    shutil.rmtree(parent, ignore_errors=True)


@contextlib.contextmanager
def build_creations(*clients: Any) -> Iterator[list[list[str]]]:
    """The components whose build containers of this project are created on each daemon while the block runs,
    read from each daemon's live event stream (a daemon keeps only its last few hundred events, which a busy
    machine overflows in the minutes an emulated build takes, so they are not read back afterwards)."""
    seen: list[list[str]] = [[] for _ in clients]
    filters = {"type": "container", "event": "create",
               "label": [f"dev.robocore.project={NAME}", "dev.robocore.role=build"]}
    streams = [client.events(decode=True, filters=filters) for client in clients]

    def collect(stream: Any, into: list[str]) -> None:
        with contextlib.suppress(Exception):  # the stream ends with an error when it is closed
            for event in stream:
                into.append(event["Actor"]["Attributes"]["dev.robocore.component"])

    threads = [threading.Thread(target=collect, args=(stream, into), daemon=True)
               for stream, into in zip(streams, seen, strict=True)]
    for thread in threads:
        thread.start()
    try:
        yield seen
    finally:
        time.sleep(1)  # events of the last moment are on their way
        for stream in streams:
            stream.close()
        for thread, into in zip(threads, seen, strict=True):
            thread.join(timeout=10)
            into.sort()


def _results(run_robocore: RobocoreCli, root: Path, *args: str) -> list[dict[str, Any]]:
    return list(json.loads(run_robocore(root, *args, "--json").stdout)["results"])


def _heard(fleet: RobotFleet, needle: str, since: float | None = None) -> list[str]:
    container = fleet.client(1).containers.get(f"{NAME}-listener")
    return [line for line in log_lines(container, HEARD, since=since) if needle in line]


def test_the_host_builds_its_talker_and_robot_b_hears_it(project: tuple[RobotFleet, Path], run_robocore: RobocoreCli,
                                                         docker_client: Any) -> None:
    fleet, root = project
    host = fleet.hosts[0]
    with build_creations(fleet.client(0), docker_client) as (on_host, here):
        done = {r["what"]: r for r in _results(run_robocore, root, "build") if r["kind"] == "build"}
    assert done["talker"]["action"] == done["listener"]["action"] == "built", done
    assert done["talker"]["reason"] == "on host robot-a: first build", done
    # the talker's build container ran on robot-a's daemon, the listener's here; never the talker's here
    assert (on_host, here) == (["talker"], ["listener"])
    assert not (root / ".robocore" / "build" / "talker" / "install").exists()  # the tree stayed there
    talker = "/root/robocore/talker/work/install/demo_talker/lib/demo_talker/talker"
    header = host.ssh(fleet, "sh", "-c", 'od -An -tu1 -j18 -N2 "$1"', "sh", talker).split()
    assert " ".join(header) == ELF_MACHINE[ARCHES["robot-a"]], header  # compiled for robot-a's arch
    recorded = host.ssh(fleet, "cat", "/root/robocore/talker/work/install/.robocore-arch").strip()
    assert recorded == ARCHES["robot-a"]

    # nothing changed: up to date, no container anywhere
    with build_creations(fleet.client(0), docker_client) as (on_host, here):
        done = {r["what"]: r["action"] for r in _results(run_robocore, root, "build") if r["kind"] == "build"}
    assert done == {"talker": "up-to-date", "listener": "up-to-date"}, done
    assert (on_host, here) == ([], [])

    synced = {r["component"]: r for r in _results(run_robocore, root, "sync") if r["kind"] == "sync"}
    assert synced["talker"]["changed"] and synced["talker"]["host"] == "robot-a", synced
    assert host.ssh(fleet, "test", "-x", "/root/robocore/talker/current/install/demo_talker/lib/demo_talker/talker",
                    check=False) == ""
    # robot-b alone: the master and the listener, no talker, nothing heard (negative control)
    run_robocore(root, "run", "--host", "robot-b", "--quiet")
    time.sleep(8)
    assert _heard(fleet, TALKER_TEXT) == []
    run_robocore(root, "run", "--host", "robot-a", "--quiet")
    talker_container = fleet.client(0).containers.get(f"{NAME}-talker")
    machine = talker_container.exec_run(["uname", "-m"]).output.decode().strip()
    assert machine == MACHINES[ARCHES["robot-a"]], machine
    assert wait_for(lambda: _heard(fleet, TALKER_TEXT), 90, 1), "robot-b never heard the talker built on robot-a"
    # a sync with nothing new keeps the release
    synced = {r["component"]: r for r in _results(run_robocore, root, "sync") if r["kind"] == "sync"}
    assert not synced["talker"]["changed"], synced


def test_a_one_line_edit_is_rebuilt_on_the_host_incrementally(project: tuple[RobotFleet, Path],
                                                              run_robocore: RobocoreCli, docker_client: Any) -> None:
    fleet, root = project
    [code] = (root / "components" / "talker").rglob("greeting.h")
    original = code.read_text()
    code.write_text(original.replace(f'"{TALKER_TEXT}"', '"built on robot-a #"'))
    with build_creations(fleet.client(0), docker_client) as (on_host, here):
        done = {r["what"]: r for r in _results(run_robocore, root, "build") if r["kind"] == "build"}
    assert done["talker"]["action"] == "built" and done["listener"]["action"] == "up-to-date", done
    assert done["talker"]["packages"] == ["demo_talker"], done  # demo_msgs was not rebuilt
    assert (on_host, here) == (["talker"], [])
    since = time.time()
    run_robocore(root, "sync", "--quiet")
    run_robocore(root, "run", "--quiet")
    assert wait_for(lambda: _heard(fleet, "built on robot-a #", since), 90, 1), "the edited talker was never heard"


def test_release_gives_each_host_its_own_arch_under_one_reference(project: tuple[RobotFleet, Path],
                                                                 run_robocore: RobocoreCli, docker_client: Any,
                                                                 tmp_path_factory: pytest.TempPathFactory) -> None:
    fleet, root = project
    original = (root / "robot.yaml").read_text()
    with serve_registry(fleet, tmp_path_factory.mktemp("registry")) as registry:
        try:
            data = yaml.safe_load(original)
            data["registry"] = registry
            (root / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
            run_robocore(root, "release", "--tag", "v1")
            for repo, hosts in (("base", ["robot-a", "robot-b"]), ("talker", ["robot-a"]), ("listener", ["robot-b"])):
                listed = manifest(registry, f"{NAME}-{repo}", "v1")
                assert listed["mediaType"] == "application/vnd.docker.distribution.manifest.list.v2+json", listed
                platforms = sorted(m["platform"]["architecture"] for m in listed["manifests"])
                assert platforms == sorted({ARCHES[h] for h in hosts}), listed
            # negative control: the list names no image of an arch nobody runs; a host asking for it gets none
            from robocore.adapters.image_delivery import pull_for_arch
            from robocore.errors import DockerError

            with pytest.raises(DockerError, match=r"no matching manifest"):
                pull_for_arch(fleet.client(1), [f"{registry}/{NAME}-listener:v1"], arch="arm64", label="robot-b")

            run_robocore(root, "run", "--tag", "v1", "--quiet")
            for index, (host, component) in enumerate((("robot-a", "talker"), ("robot-b", "listener"))):
                container = fleet.client(index).containers.get(f"{NAME}-{component}")
                assert container.attrs["Config"]["Image"] == f"{registry}/{NAME}-{component}:v1"
                machine = container.exec_run(["uname", "-m"]).output.decode().strip()
                assert machine == MACHINES[ARCHES[host]], (host, machine)
                image = fleet.client(index).images.get(f"{registry}/{NAME}-{component}:v1")
                assert image.attrs["Architecture"] == ARCHES[host]
            assert wait_for(lambda: _heard(fleet, TALKER_TEXT, time.time() - 20) or
                            _heard(fleet, "built on robot-a #", time.time() - 20), 90, 1)
        finally:
            (root / "robot.yaml").write_text(original)
            for image in docker_client.images.list():
                for tag in image.tags:
                    if tag.startswith(f"{registry}/"):
                        docker_client.images.remove(tag)
