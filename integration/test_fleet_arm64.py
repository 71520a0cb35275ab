"""An arm64 ROS 1 robot in a Swarm fleet, on this amd64 machine through qemu.

The template's noetic project on the debian base (``robocore-it-arm64``, the arm64 suites' project: its arm64 root,
base and talker images are the ones made in the background, :mod:`arm64_project`) as a fleet model of one arm64
host: the ROS master, the roscpp talker and the rospy listener all on it. One swarm: a Docker-in-Docker manager
and one DinD robot host (robot ``a1``, labelled arm64 by ``fleet join``), whose dockerd runs the arm64 containers
through the kernel's qemu-aarch64 entry as an arm64 robot's daemon runs them natively.

``release --fleet`` builds each component's self-contained arm64 image (staged image + install tree layer) and
pushes it and the arm64 base to Debian's docker-registry (local_registry), recorded by digest; the robot pulls
them from there (nothing is synced). In order, on the same swarm:

1. join: the robot's node labelled with its project, robot, host and ``arm64``;
2. v1 rolled out: healthy through the ROS 1 gate (the probe, in the arm64 base on the robot, asks the robot's
   master for /talker and /listener, pings them, and hears /chatter with rospy); the listener heard the talker;
   master, talker and listener run arm64 images by digest (``uname -m``: aarch64);
3. v2 (the talker says "v2", rebuilt for arm64): rolled out, healthy, heard saying v2;
4. negative control: v3, whose talker runs but is no ROS node (its binary a shell script that sleeps): every
   container runs, yet the gate fails with "/talker" missing and "/chatter" not heard, the rollout stops and the
   robot is back on v2, gated again and heard.
"""

from __future__ import annotations

import json
import shutil
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
import yaml
from arm64_project import NAME, init_project
from deploy_helpers import wait_for
from local_registry import registry_tunnels, serve_registry
from swarm_fleet import listener_lines, parallel, remove_pushed_tags

if TYPE_CHECKING:
    from conftest import RobocoreCli
    from robot_host.hosts import RobotFleet

pytestmark = [pytest.mark.docker, pytest.mark.timeout(1800)]

ROBOT = "a1"
#: The greeting's header in the talker's workspace (what v2 changes).
GREETING_H = "components/talker/src/demo_talker/include/demo_talker/greeting.h"
#: Seconds a robot's gate may take: pulling the arm64 base and starting everything under emulation.
ROBOT_TIMEOUT = 240
#: The robot timeout of the negative control: its probe waits this long (less the time to start) for a node that
#: never comes.
CONTROL_TIMEOUT = 60


@dataclass(frozen=True)
class ArmFleet:
    """The module's hosts (0: the manager, 1: the arm64 robot host) and the fleet's project folder."""

    hosts: RobotFleet
    root: Path
    timings: dict[str, float]

    def heard(self, since: float | None = None) -> list[str]:
        """What the robot's listener logged lately (since ``since``, a time.time(), when given), read on its host."""
        if since is None:
            return listener_lines(self.hosts, 1, NAME, ROBOT)
        out = self.on_robot(f"docker ps -q --filter label=com.docker.swarm.service.name={NAME}-{ROBOT}-listener | "
                            f"head -1 | xargs -r docker logs --since {int(since)} 2>&1")
        return [line for line in out.splitlines() if "I heard" in line]

    def on_robot(self, script: str) -> str:
        return self.hosts.hosts[1].ssh(self.hosts, "sh", "-c", script)


def write_fleet(root: Path, manager: str, robot_ip: str, registry: str, robot_timeout: int = ROBOT_TIMEOUT) -> None:
    fleet = {
        "engine": "swarm",
        "manager": {"ip": manager, "user": "root"},
        "registry": registry,
        "robots": [{"name": ROBOT, "hosts": {"robot": {"ip": robot_ip}}}],
        "rollout": {
            "health": {"running": 3, "nodes": ["/talker", "/listener"], "heard": ["/chatter"]},
            "timeouts": {"robot": robot_timeout, "wave": 600},
        },
    }
    (root / "fleet.yaml").write_text(yaml.safe_dump(fleet, sort_keys=False))


def timed(timings: dict[str, float], step: str, action: Callable[[], Any]) -> Any:
    started = time.monotonic()
    try:
        return action()
    finally:
        timings[step] = round(time.monotonic() - started, 1)


def push_early(docker_client: Any, image: str, ref: str) -> None:
    """Push ``image`` (the arm64 base the background made) as ``ref`` while the project is staged and built, so that
    ``release --fleet`` finds its ~800 MB of layers in the registry already; nothing when it is not there yet (the
    release then pushes it itself)."""
    from docker.errors import ImageNotFound

    try:
        docker_client.images.get(image).tag(ref)
    except ImageNotFound:
        return
    repo, tag = ref.rsplit(":", 1)
    for line in docker_client.images.push(repo, tag=tag, stream=True, decode=True):
        assert "error" not in line, line


@pytest.fixture(scope="module")
def arm(robot_fleets: Callable[..., RobotFleet], docker_client: Any, run_robocore: RobocoreCli,
        tmp_path_factory: pytest.TempPathFactory, arm64_images: None) -> Iterator[ArmFleet]:
    """The hosts (started while the project is staged, built and released as v1; the arm64 base pushed meanwhile)
    and the fleet project."""
    timings: dict[str, float] = {}
    with parallel(2) as pool, serve_registry(None, tmp_path_factory.mktemp("arm-registry")) as registry:
        started = pool.submit(robot_fleets, 2)
        early = pool.submit(push_early, docker_client, f"{NAME}-base:latest-arm64", f"{registry}/{NAME}-base:early")
        try:
            root = tmp_path_factory.mktemp("fleet-arm64") / NAME
            init_project(root, [{"name": "robot", "ip": "192.0.2.10", "user": "root", "arch": "arm64"}],
                         talker_host="robot", server_host="robot")
            write_fleet(root, "192.0.2.2", "192.0.2.10", registry)  # the hosts' addresses once they are up
            for step in ("prepare-base", "stage", "build"):
                timed(timings, step, lambda s=step: run_robocore(root, s, "--quiet"))
            timed(timings, "base pushed early (waited for)", early.result)
            timed(timings, "release v1", lambda: run_robocore(root, "release", "--fleet", "--tag", "v1"))
            hosts = timed(timings, "hosts (waited for)", started.result)
            write_fleet(root, hosts.hosts[0].ip, hosts.hosts[1].ip, registry)
            with registry_tunnels(hosts, registry):
                yield ArmFleet(hosts, root, timings)
        finally:
            print("arm64 fleet steps (s):", timings)
            remove_pushed_tags(docker_client, registry)


def rollout(arm: ArmFleet, run_robocore: RobocoreCli, version: str, *,
            plain: bool = False) -> tuple[int, dict[str, str], str]:
    """``fleet rollout VERSION --json`` (``plain``: without ``--json``, whose progress lines go to stderr): exit
    code, robot -> verdict (from the JSON), stderr."""
    flags = () if plain else ("--json",)
    proc = timed(arm.timings, f"rollout {version}",
                 lambda: run_robocore(arm.root, "fleet", "rollout", version, *flags, check=False))
    if plain:
        return proc.returncode, {}, proc.stderr
    results = json.loads(proc.stdout)["results"] if proc.stdout.strip() else []
    verdicts = {o["robot"]: o["verdict"] for o in results if o["kind"] == "fleet_robot_change"}
    return proc.returncode, verdicts, proc.stderr


def release(arm: ArmFleet, run_robocore: RobocoreCli, version: str) -> None:
    """``stage`` (a no-op unless another run on this machine staged the shared listener image for amd64 meanwhile),
    then ``release --fleet --tag VERSION``."""
    timed(arm.timings, f"stage, release {version}", lambda: (run_robocore(arm.root, "stage", "--quiet"),
                                                             run_robocore(arm.root, "release", "--fleet", "--tag",
                                                                          version)))


def status_row(arm: ArmFleet, run_robocore: RobocoreCli) -> dict[str, Any]:
    envelope = json.loads(run_robocore(arm.root, "fleet", "status", "--json").stdout)
    [row] = [r for r in envelope["results"] if r["kind"] == "fleet_robot"]
    return dict(row)


def test_join_labels_the_robot_node_arm64(arm: ArmFleet, run_robocore: RobocoreCli) -> None:
    done = json.loads(run_robocore(arm.root, "fleet", "join", "--json").stdout)
    assert {(r["robot"], r["host"], r["action"]) for r in done["results"]} == {(ROBOT, "robot", "joined")}, done
    labels = arm.hosts.hosts[0].ssh(arm.hosts, "sh", "-c", "docker node ls -q | xargs docker node inspect "
                                    "--format '{{.Description.Hostname}} {{json .Spec.Labels}}'")
    by_host = {line.split(" ", 1)[0]: json.loads(line.split(" ", 1)[1]) or {} for line in labels.splitlines()}
    assert by_host[arm.hosts.hosts[1].name] == {"dev.robocore.project": NAME, "dev.robocore.robot": ROBOT,
                                                "dev.robocore.host": "robot", "dev.robocore.arch": "arm64"}, by_host


def test_v1_runs_arm64_by_digest_and_is_heard_through_the_robots_master(arm: ArmFleet,
                                                                         run_robocore: RobocoreCli) -> None:
    record = json.loads((arm.root / ".robocore" / "releases" / "v1.json").read_text())
    assert {c: sorted(images) for c, images in record["components"].items()} == \
        {"talker": ["arm64"], "listener": ["arm64"]} and sorted(record["base"]) == ["arm64"], record
    code, verdicts, stderr = rollout(arm, run_robocore, "v1")
    assert code == 0 and verdicts == {ROBOT: "healthy"}, stderr
    assert wait_for(lambda: [line for line in arm.heard() if "hello from talker" in line], 60), arm.heard()
    for part, image in (("discovery-0", record["base"]["arm64"]), ("talker", record["components"]["talker"]["arm64"]),
                        ("listener", record["components"]["listener"]["arm64"])):
        service = f"{NAME}-{ROBOT}-{part}"
        out = arm.on_robot(f"c=$(docker ps -q --filter label=com.docker.swarm.service.name={service} | head -1); "
                           "docker inspect --format '{{.Config.Image}} {{.Image}}' $c | "
                           "{ read ref id; echo $ref; docker image inspect --format '{{.Architecture}}' $id; }; "
                           "docker exec $c uname -m")
        assert out.split() == [image, "arm64", "aarch64"], (part, out)
    assert "robocore" not in arm.on_robot("ls -A /root").split()  # nothing synced
    row = status_row(arm, run_robocore)
    assert (row["running"], row["target"], row["health"]) == ("v1", "v1", "healthy"), row


def test_v2_rebuilt_for_arm64_rolls_out_and_is_heard(arm: ArmFleet, run_robocore: RobocoreCli) -> None:
    header = arm.root / GREETING_H
    header.write_text(header.read_text().replace('"hello from talker #"', '"hello v2 from talker #"'))
    timed(arm.timings, "build talker v2",
          lambda: run_robocore(arm.root, "build", "--component", "talker", "--quiet"))
    release(arm, run_robocore, "v2")
    code, verdicts, stderr = rollout(arm, run_robocore, "v2")
    assert code == 0 and verdicts == {ROBOT: "healthy"}, stderr
    assert wait_for(lambda: [line for line in arm.heard() if "hello v2 from talker" in line], 60), arm.heard()
    row = status_row(arm, run_robocore)
    assert (row["running"], row["target"], row["health"]) == ("v2", "v2", "healthy"), row


def test_a_talker_that_is_no_ros_node_fails_the_ros1_gate_and_goes_back(arm: ArmFleet,
                                                                         run_robocore: RobocoreCli) -> None:
    install = arm.root / ".robocore" / "build" / "talker" / "install"
    [binary] = [p for p in install.rglob("talker") if p.is_file() and not p.is_symlink()]
    saved = binary.with_name("talker.arm64")
    shutil.move(binary, saved)
    try:  # v3: the talker's container runs (a shell that sleeps), but no /talker node, nothing on /chatter
        binary.write_text("#!/bin/sh\nexec sleep 100000\n")
        binary.chmod(0o755)
        release(arm, run_robocore, "v3")
    finally:
        binary.unlink(missing_ok=True)
        shutil.move(saved, binary)
    fleet_file = arm.root / "fleet.yaml"
    original = fleet_file.read_text()
    data = yaml.safe_load(original)
    data["rollout"]["timeouts"]["robot"] = CONTROL_TIMEOUT  # the probe waits this long for the missing node
    fleet_file.write_text(yaml.safe_dump(data, sort_keys=False))
    try:
        code, _, stderr = rollout(arm, run_robocore, "v3", plain=True)
    finally:
        fleet_file.write_text(original)
    assert code != 0 and "Traceback" not in stderr, stderr
    assert "nodes missing: /talker" in stderr and "not heard: /chatter" in stderr, stderr
    assert "/listener" not in stderr.split("nodes missing:", 1)[1].split(";")[0], stderr  # only the talker
    assert f"{ROBOT}: back on v2: healthy" in stderr, stderr  # gated again: the ROS 1 probe passes on v2
    row = status_row(arm, run_robocore)
    assert (row["running"], row["target"], row["health"]) == ("v2", "v2", "rolled-back"), row
    # heard again after the rollback (the listener, unchanged by v3, kept running throughout)
    back = time.time()
    assert wait_for(lambda: any("hello v2 from talker" in line for line in arm.heard(back)), 60), arm.heard()
    print("arm64 fleet steps (s):", arm.timings)
