"""A mixed-architecture ROS 1 robot: an amd64 host and an arm64 host, on this amd64 machine through qemu.

The template's noetic project on the debian base, with two Docker-in-Docker robot hosts: robot-x86 (amd64: the
ROS master and the rospy listener) and robot-arm (arm64: the roscpp talker). robot-arm's dockerd runs on this
amd64 kernel and runs arm64 containers through the kernel's qemu-aarch64 binfmt_misc entry (flag F), as an
arm64 robot's own daemon would run them natively.

- ``prepare-base`` makes one base per arch, each really of its arch (image ``Architecture``), from a Debian root
  bootstrapped per arch (``robocore/<arch>/debian:bookworm-debian``); ``build`` compiles the talker for arm64 in an
  emulated container: its install tree holds an aarch64 ELF and records ``arm64``;
- ``sync`` and ``run``: the listener on robot-x86 hears the talker on robot-arm through the master, ``status``
  lists both nodes, ``uname -m`` in the talker's live container says ``aarch64`` (and in its dev shell on this
  machine); ``doctor`` says robot-arm runs
  arm64 emulated and robot-x86 amd64 natively;
- negative controls: the talker's install tree swapped for the listener's (amd64), and an amd64 ELF put in
  place of the talker binary, are refused by ``sync`` in one line, and the host keeps its release;
- the same robot's graph tests through the pytest plugin (``nox -s graph``): the template's ROS 1 graph tests
  plus ``robot.exec(..., ["uname", "-m"])``: ``aarch64`` in the talker, ``x86_64`` in the listener;
- last, the same project as a robot with no x86 computer (robot-arm its only host): the ROS master runs the arm64
  base on robot-arm, the listener is rebuilt for arm64, and it hears the talker through that master; with the
  master stopped, a restarted listener hears nothing (the negative control).

The arm64 root and base are built once per machine (content-hash labels): the first run of this module
bootstraps the arm64 root under emulation (several minutes), later runs reuse it.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
import yaml
from arm64_project import NAME, init_project
from deploy_helpers import HEARD, log_lines, remove_project_containers, run_nox, wait_for

from robocore.plan import arches

if TYPE_CHECKING:
    from conftest import RobocoreCli
    from robot_host.hosts import RobotFleet

# the first run on a machine bootstraps the arm64 root and base under emulation: more than the suite's 25 minutes
# per test on a busy 2-core machine (CI stops itself at 80 minutes whatever happens)
pytestmark = [pytest.mark.docker, pytest.mark.timeout(3000)]

TALKER_TEXT = "hello from talker #"
HOSTS = ("robot-x86", "robot-arm")

GRAPH_ARCH_TESTS = '''\
"""Each component runs on its host's arch: the talker's image is arm64 (emulated here), the listener's amd64."""


def test_the_talker_runs_aarch64(robot):
    code, out = robot.exec("talker", ["uname", "-m"])
    assert code == 0 and out.strip() == "aarch64", out


def test_the_listener_runs_x86_64(robot):
    code, out = robot.exec("listener", ["uname", "-m"])
    assert code == 0 and out.strip() == "x86_64", out
'''


@pytest.fixture(scope="module")
def mixed(robot_fleets: Callable[..., RobotFleet], docker_client: Any, run_robocore: RobocoreCli,
          tmp_path_factory: pytest.TempPathFactory, arm64_images: None) -> Any:
    """The noetic project with the talker on an arm64 host, after prepare-base, stage, build and sync."""
    fleet = robot_fleets(2)
    root = tmp_path_factory.mktemp("arm64") / NAME
    hosts = [{"name": name, "ip": host.ip, "user": "root", "arch": arch}
             for name, host, arch in zip(HOSTS, fleet.hosts, ("amd64", "arm64"), strict=True)]
    init_project(root, hosts, talker_host="robot-arm", server_host="robot-x86")
    (root / "tests" / "graph" / "test_arches.py").write_text(GRAPH_ARCH_TESTS)
    timings = {}
    for step in ("prepare-base", "stage", "build", "sync"):
        started = time.monotonic()
        done = json.loads(run_robocore(root, step, "--json").stdout)
        timings[step] = time.monotonic() - started
        for result in done["results"]:  # each image and build, with its seconds
            if result.get("seconds") is not None:
                print(f"{step}: {result.get('what')} {result.get('action')} {result['seconds']:.1f} s")
    print("arm64 robot set-up (s):", {k: round(v, 1) for k, v in timings.items()})
    yield fleet, root
    remove_project_containers(docker_client, NAME)


def _talker_elves(root: Path) -> list[Path]:
    install = root / ".robocore" / "build" / "talker" / "install"
    return [p for p in install.rglob("talker") if p.is_file() and not p.is_symlink()
            and arches.elf_arch(p.read_bytes()[:20]) is not None]


def test_every_image_and_tree_is_of_its_hosts_arch(mixed: Any, docker_client: Any, run_robocore: RobocoreCli) -> None:
    _, root = mixed
    images = {ref: docker_client.images.get(ref).attrs["Architecture"] for ref in (
        "robocore/arm64/debian:bookworm-debian", "robocore/amd64/debian:bookworm-debian",
        f"{NAME}-base:latest-arm64", f"{NAME}-base:latest", f"{NAME}-talker:latest", f"{NAME}-listener:latest")}
    assert images == {
        "robocore/arm64/debian:bookworm-debian": "arm64", "robocore/amd64/debian:bookworm-debian": "amd64",
        f"{NAME}-base:latest-arm64": "arm64", f"{NAME}-base:latest": "amd64",
        f"{NAME}-talker:latest": "arm64", f"{NAME}-listener:latest": "amd64"}, images
    machine = docker_client.containers.run(f"{NAME}-base:latest-arm64", ["uname", "-m"], remove=True,
                                           platform="linux/arm64").decode().strip()
    assert machine == "aarch64"
    [talker] = _talker_elves(root)
    assert arches.elf_arch(talker.read_bytes()[:20]) == "arm64"
    described = subprocess.run(["file", "-b", str(talker)], capture_output=True, text=True, check=False).stdout
    assert "aarch64" in described, described
    install = root / ".robocore" / "build"
    assert (install / "talker" / "install" / arches.INSTALL_ARCH_FILE).read_text().strip() == "arm64"
    assert (install / "listener" / "install" / arches.INSTALL_ARCH_FILE).read_text().strip() == "amd64"
    assert (root / ".robocore" / "ccache" / "arm64").is_dir()
    # the debian base's build trees are Ninja's: an incremental build under qemu is one process, not make's many
    assert (install / "talker" / "build" / "demo_talker" / "build.ninja").is_file()
    # the dev shell of the arm64 talker, on this amd64 machine: its own image, emulated
    inside = run_robocore(root, "shell", "--component", "talker", "--cmd", "uname -m").stdout
    assert inside.strip().splitlines()[-1] == "aarch64", inside


def test_roots_are_byte_compiled_once_and_py3compile_is_back(mixed: Any, docker_client: Any) -> None:
    """The roots are bootstrapped with py3compile diverted and one compileall at the end: the python3 packages'
    modules load from their bytecode, and py3compile is in place, with no diversion left, for later packages."""
    for arch in ("arm64", "amd64"):
        script = ("python3 -B -v -c 'import rospy' 2>&1 | grep -c 'code object from .*rospy/__pycache__/' ; "
                  "command -v py3compile ; dpkg-divert --list '*py3compile*' | wc -l")
        out = docker_client.containers.run(f"robocore/{arch}/debian:bookworm-debian", ["sh", "-c", script],
                                           remove=True, platform=f"linux/{arch}").decode().split()
        assert int(out[0]) > 3 and out[1:] == ["/usr/bin/py3compile", "0"], (arch, out)


def test_arm64_talker_heard_by_amd64_listener_through_the_master(mixed: Any, run_robocore: RobocoreCli) -> None:
    fleet, root = mixed
    run_robocore(root, "run", "--quiet")

    def heard() -> list[str]:
        lines = log_lines(fleet.client(0).containers.get(f"{NAME}-listener"), HEARD)
        return [line for line in lines if TALKER_TEXT in line]

    assert wait_for(heard, 180, 1), "the listener on robot-x86 never heard the arm64 talker on robot-arm"
    status = json.loads(run_robocore(root, "status", "--json", "--nodes", check=False).stdout)
    [graph] = [r for r in status["results"] if r["kind"] == "ros_graph"]
    assert {"/talker", "/listener"} <= set(graph["nodes"] or []), graph
    inside = run_robocore(root, "connect", "--component", "talker", "--cmd", "uname -m").stdout
    assert inside.strip().splitlines()[-1] == "aarch64", inside
    on_arm = fleet.client(1).images.get(f"{NAME}-talker:latest").attrs["Architecture"]
    assert on_arm == "arm64"
    doctor = json.loads(run_robocore(root, "doctor", "--json", check=False).stdout)
    facts = {r["host"]: " / ".join(r["facts"]) for r in doctor["results"] if "facts" in r}
    assert "arm64 emulated (qemu-aarch64 on amd64)" in facts["robot-arm"], facts
    assert "amd64 native" in facts["robot-x86"], facts


def test_sync_refuses_an_install_tree_of_another_arch(mixed: Any, run_robocore: RobocoreCli) -> None:
    fleet, root = mixed
    out = root / ".robocore" / "build"
    install = out / "talker" / "install"
    saved = out / "talker" / "install.arm64"
    before = fleet.hosts[1].ssh(fleet, "readlink", "/root/robocore/talker/current", check=False)
    shutil.move(install, saved)
    try:
        # the listener's tree (built for amd64) in place of the talker's
        shutil.copytree(out / "listener" / "install", install, symlinks=True)
        refused = run_robocore(root, "sync", "--host", "robot-arm", check=False)
        assert refused.returncode == 2, refused.stdout + refused.stderr
        lines = [line for line in refused.stderr.splitlines() if line.strip() and "hint" not in line.lower()]
        assert len(lines) == 1 and "was built for amd64, but host robot-arm is arm64" in lines[0], refused.stderr
        # the arm64 tree with an amd64 ELF in place of the talker: the ELF headers give it away
        shutil.rmtree(install)
        shutil.copytree(saved, install, symlinks=True)
        [talker] = _talker_elves(root)
        shutil.copyfile("/bin/true", talker)
        refused = run_robocore(root, "sync", "--host", "robot-arm", check=False)
        assert refused.returncode == 2 and "mixes arches (arm64 and" in refused.stderr, refused.stderr
        assert "(amd64)" in refused.stderr, refused.stderr
    finally:
        shutil.rmtree(install, ignore_errors=True)
        shutil.move(saved, install)
    after = fleet.hosts[1].ssh(fleet, "readlink", "/root/robocore/talker/current", check=False)
    assert after == before, "a refused sync changed the host's release"
    run_robocore(root, "sync", "--host", "robot-arm", "--quiet")  # the real tree still goes


def test_graph_tests_of_the_mixed_robot_through_the_plugin(mixed: Any) -> None:
    _, root = mixed
    done = run_nox(root, "graph", "--", "-v", "-p", "no:cacheprovider")
    output = done.stdout + done.stderr
    assert done.returncode == 0, output[-6000:]
    for test in ("test_the_talker_runs_aarch64", "test_the_listener_runs_x86_64",
                 "test_talker_and_listener_are_in_the_graph", "test_listener_hears_what_the_test_publishes"):
        assert f"{test} PASSED" in output, output[-6000:]


def _only_arm64(root: Path, ip: str) -> None:
    """robot.yaml of ``root`` with one host, robot-arm (arm64) at ``ip``: the ROS master, the talker and the
    listener all on it."""
    data = yaml.safe_load((root / "robot.yaml").read_text())
    data["hosts"] = [{"name": "robot-arm", "ip": ip, "user": "root", "arch": "arm64"}]
    data["discovery"] = {"servers": [{"host": "robot-arm"}]}
    for comp in data["components"]:
        comp["runs_on"] = "robot-arm"
    (root / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))


def test_a_robot_with_no_x86_host_runs_its_master_and_nodes_on_arm64(mixed: Any, run_robocore: RobocoreCli) -> None:
    """The same project made a robot of one arm64 computer (a single Jetson or Pi): the ROS master, the C++ talker
    and the Python listener all run arm64 on robot-arm, the listener hears the talker, ``status`` lists both.
    Negative control: with that master stopped, a restarted listener hears nothing (it cannot register), so what
    it heard went through the master on the arm64 host. Last of the module: it takes the mixed robot down."""
    fleet, root = mixed
    run_robocore(root, "down", "--quiet")
    _only_arm64(root, fleet.hosts[1].ip)
    validated = run_robocore(root, "validate")
    assert "ok" in validated.stdout + validated.stderr
    timings = {}
    outcomes = {}
    for step in ("prepare-base", "stage", "build", "sync"):
        started = time.monotonic()
        done = json.loads(run_robocore(root, step, "--json").stdout)
        timings[step] = round(time.monotonic() - started, 1)
        outcomes[step] = {str(r.get("what")): r.get("action") for r in done["results"] if r.get("what")}
    print("all-arm64 robot set-up (s):", timings, outcomes)
    # the dev machine (amd64) makes no amd64 base for a robot with no amd64 host: the arm64 base is reused
    bases = outcomes["prepare-base"]
    assert bases == {f"{NAME}-base:latest-arm64": "up-to-date"}, bases
    compose = yaml.safe_load((root / ".robocore" / "compose" / "robot-arm.yaml").read_text())
    assert compose["services"]["discovery-0"]["image"] == f"{NAME}-base:latest-arm64"
    install = root / ".robocore" / "build"
    assert (install / "listener" / "install" / arches.INSTALL_ARCH_FILE).read_text().strip() == "arm64"

    run_robocore(root, "run", "--quiet")
    arm = fleet.client(1)

    def heard(since: float | None = None) -> list[str]:
        lines = log_lines(arm.containers.get(f"{NAME}-listener"), HEARD, since)
        return [line for line in lines if TALKER_TEXT in line]

    assert wait_for(heard, 180, 1), "the arm64 listener never heard the arm64 talker through the arm64 master"
    for name in (f"{NAME}-discovery-0", f"{NAME}-talker", f"{NAME}-listener"):
        container = arm.containers.get(name)
        assert arm.images.get(container.attrs["Config"]["Image"]).attrs["Architecture"] == "arm64", name
        code, out = container.exec_run(["uname", "-m"])
        assert (code, out.decode().strip()) == (0, "aarch64"), (name, out)
    assert arm.containers.get(f"{NAME}-discovery-0").attrs["Config"]["Image"] == f"{NAME}-base:latest-arm64"
    status = json.loads(run_robocore(root, "status", "--json", "--nodes", check=False).stdout)
    [graph] = [r for r in status["results"] if r["kind"] == "ros_graph"]
    assert {"/talker", "/listener"} <= set(graph["nodes"] or []), graph
    assert "robot-arm" in graph["via"], graph

    # negative control: the master stopped, a listener that starts again cannot register, so hears nothing
    arm.containers.get(f"{NAME}-discovery-0").stop(timeout=5)
    listener = arm.containers.get(f"{NAME}-listener")
    listener.restart(timeout=5)
    restarted = time.time()
    time.sleep(20)
    assert listener.reload() is None and listener.status == "running"
    assert heard(restarted + 1) == [], "a listener with the master stopped heard the talker: not through the master"
    down = json.loads(run_robocore(root, "status", "--json", "--nodes", check=False).stdout)
    [graph] = [r for r in down["results"] if r["kind"] == "ros_graph"]
    assert graph["nodes"] is None and "the ROS master is down" in graph["via"], graph
