"""A fleet on Docker Swarm: simulated robot hosts joined to a swarm, releases rolled out in waves behind the gate.

One swarm for the module: a Docker-in-Docker host of its own as the manager (a manager's advertise address may
not be loopback, and this machine's daemon is shared), and one DinD host per robot, reached over ssh:// as real
robots are. Each robot is the demo project (discovery server, talker, listener on its host). Releases are
self-contained images (component image + its install tree) pushed to Debian's docker-registry, which every host
reaches as the same 127.0.0.1:PORT (local_registry); services name them by digest, so no robot is synced.

The tests run in order on the same swarm: join; v1 to every robot; v2 with the last robot cut off (pending,
then converging alone once reconnected); a canary whose v3 crashes (the rollout stops, the canary is back on v2,
later waves untouched); a device component refused before anything changes.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml
from conftest import RobocoreCli
from deploy_helpers import wait_for
from local_registry import serve_registry
from robot_host.hosts import RobotFleet
from swarm_fleet import cut, listener_lines, make_project, make_releases, prepull

ROBOTS = 6
PROJECT = "robocore-it-swarm"


@pytest.fixture(scope="module")
def swarm_hosts(robot_fleets: Callable[..., RobotFleet]) -> RobotFleet:
    """Host 0 is the manager, hosts 1..ROBOTS the robots r1..r6."""
    return robot_fleets(ROBOTS + 1)


@pytest.fixture(scope="module")
def registry(swarm_hosts: RobotFleet, tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """The release registry, 127.0.0.1:PORT on this machine and on every host."""
    with serve_registry(swarm_hosts, tmp_path_factory.mktemp("swarm-registry")) as address:
        yield address


@pytest.fixture(scope="module")
def fleet_project(demo_project: Path, swarm_hosts: RobotFleet, registry: str, docker_client: Any,
                  tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The demo project as a fleet of ROBOTS one-host robots in three waves, with release records v1, v2 (the
    talker says v2) and v3 (the talker exits 3 at start)."""
    waves = [{"name": "canary", "robots": ["r1"]}, {"name": "half", "percent": 50}, {"name": "rest"}]
    root = make_project(demo_project, tmp_path_factory.mktemp("swarm"), PROJECT, swarm_hosts, registry, waves=waves)
    make_releases(docker_client, demo_project, root, registry, tmp_path_factory.mktemp("swarm-images"),
                  {"v1": "same", "v2": "v2", "v3": "crash"})
    prepull(swarm_hosts, root, "v1")
    return root


def status_rows(run_robocore: RobocoreCli, root: Path) -> dict[str, dict[str, Any]]:
    """``fleet status --json``: robot -> row."""
    proc = run_robocore(root, "fleet", "status", "--json")
    envelope = json.loads(proc.stdout)
    assert envelope["ok"] is True, envelope
    return {r["robot"]: r for r in envelope["results"] if r["kind"] == "fleet_robot"}


def service_tasks(hosts: RobotFleet, robot: str) -> dict[str, str]:
    """``robot``'s running tasks (ids) and its services' spec versions: unchanged means the robot was not touched
    (ended tasks are left out: Swarm prunes its task history on its own)."""
    out = hosts.hosts[0].ssh(hosts, "sh", "-c", f"docker service ls -q --filter label=dev.robocore.robot={robot} | "
                             "xargs -r docker service ps -q --no-trunc --filter desired-state=running")
    versions = hosts.hosts[0].ssh(hosts, "sh", "-c", f"docker service ls -q --filter label=dev.robocore.robot={robot}"
                                  " | xargs -r docker service inspect --format '{{.Version.Index}}'")
    return {"tasks": " ".join(sorted(out.split())), "versions": " ".join(sorted(versions.split()))}


def test_join_labels_every_robot_node_and_is_idempotent(fleet_project: Path, swarm_hosts: RobotFleet,
                                                       run_robocore: RobocoreCli) -> None:
    first = json.loads(run_robocore(fleet_project, "fleet", "join", "--json").stdout)
    assert first["ok"] is True
    assert {r["robot"] for r in first["results"]} == {f"r{i}" for i in range(1, ROBOTS + 1)}
    labels = swarm_hosts.hosts[0].ssh(swarm_hosts, "sh", "-c", "docker node ls -q | xargs docker node inspect "
                                      "--format '{{json .Spec.Labels}}'")
    robots = sorted(json.loads(line).get("dev.robocore.robot", "") for line in labels.splitlines())
    assert robots == ["", *sorted(f"r{i}" for i in range(1, ROBOTS + 1))]  # the manager carries none
    again = json.loads(run_robocore(fleet_project, "fleet", "join", "--json").stdout)
    assert {r["action"] for r in again["results"]} == {"unchanged"}


def test_v1_rolls_out_to_every_robot_by_digest_and_is_heard(fleet_project: Path, swarm_hosts: RobotFleet,
                                                            run_robocore: RobocoreCli) -> None:
    proc = run_robocore(fleet_project, "fleet", "rollout", "v1", "--json")
    outcomes = json.loads(proc.stdout)["results"]
    assert {o["robot"]: o["verdict"] for o in outcomes} == {f"r{i}": "healthy" for i in range(1, ROBOTS + 1)}
    assert [o["wave"] for o in outcomes] == ["canary", "half", "half", "half", "rest", "rest"]
    rows = status_rows(run_robocore, fleet_project)
    assert {r: (row["running"], row["target"], row["state"]) for r, row in rows.items()} == \
        {f"r{i}": ("v1", "v1", "online") for i in range(1, ROBOTS + 1)}
    for index in range(1, ROBOTS + 1):  # heard on every robot, read on the robot itself
        assert wait_for(lambda i=index: listener_lines(swarm_hosts, i, PROJECT), 30), f"r{index} heard nothing"
        image = swarm_hosts.hosts[index].ssh(swarm_hosts, "sh", "-c", "docker ps -q --filter label=com.docker.swarm."
                                             f"service.name={PROJECT}-r{index}-talker | xargs docker inspect "
                                             "--format '{{.Config.Image}}'")
        assert "@sha256:" in image, image  # by digest
        assert "robocore" not in swarm_hosts.hosts[index].ssh(swarm_hosts, "ls", "-A", "/root").split()  # no sync
    text = run_robocore(fleet_project, "fleet", "status").stdout
    assert text.splitlines()[0].split()[:3] == ["ROBOT", "RUNNING", "TARGET"]


def test_offline_robot_is_pending_then_converges_alone(fleet_project: Path, swarm_hosts: RobotFleet,
                                                        run_robocore: RobocoreCli) -> None:
    cut(swarm_hosts, ROBOTS, True)
    try:
        def down() -> bool:
            return status_rows(run_robocore, fleet_project)[f"r{ROBOTS}"]["state"].startswith("offline")

        assert wait_for(down, 60, interval=2), "the manager never saw the cut robot down"
        started = time.monotonic()
        proc = run_robocore(fleet_project, "fleet", "rollout", "v2", "--json")
        took = time.monotonic() - started
        verdicts = {o["robot"]: o["verdict"] for o in json.loads(proc.stdout)["results"]}
        assert verdicts == {**{f"r{i}": "healthy" for i in range(1, ROBOTS)}, f"r{ROBOTS}": "pending"}, proc.stdout
        assert took < 240, took
        row = status_rows(run_robocore, fleet_project)[f"r{ROBOTS}"]
        # the manager drops a down node's tasks: what it runs is unknown until it is back
        assert (row["running"], row["target"], row["state"]) == ("?", "v2", "offline, pending"), row
        # its containers were left alone: still the v1 talker, still running
        container = swarm_hosts.hosts[ROBOTS].container.get_wrapped_container()
        code, out = container.exec_run(["docker", "ps", "--filter",
                                        f"label=com.docker.swarm.service.name={PROJECT}-r{ROBOTS}-talker",
                                        "--format", "{{.Image}} {{.Status}}"])
        assert code == 0 and "Up" in out.decode(), out
    finally:
        cut(swarm_hosts, ROBOTS, False)

    def converged() -> bool:
        row = status_rows(run_robocore, fleet_project)[f"r{ROBOTS}"]
        return (row["running"], row["state"]) == ("v2", "online")

    assert wait_for(converged, 120, interval=2), status_rows(run_robocore, fleet_project)[f"r{ROBOTS}"]
    assert wait_for(lambda: any("hello v2" in line for line in listener_lines(swarm_hosts, ROBOTS, PROJECT)), 60), \
        listener_lines(swarm_hosts, ROBOTS, PROJECT)


def test_canary_that_crashes_stops_the_rollout_and_goes_back(fleet_project: Path, swarm_hosts: RobotFleet,
                                                             run_robocore: RobocoreCli) -> None:
    before = {f"r{i}": service_tasks(swarm_hosts, f"r{i}") for i in range(2, ROBOTS + 1)}
    proc = run_robocore(fleet_project, "fleet", "rollout", "v3", check=False)
    assert proc.returncode != 0
    assert "stopped in wave canary" in proc.stderr and "r1" in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr
    assert "r1: back on v2: healthy" in proc.stderr, proc.stderr  # gated again: running, nodes present, heard

    def back() -> dict[str, Any] | None:
        row = status_rows(run_robocore, fleet_project)["r1"]
        return row if (row["running"], row["target"], row["health"]) == ("v2", "v2", "rolled-back") else None

    assert wait_for(back, 30, interval=1), status_rows(run_robocore, fleet_project)["r1"]
    rows = status_rows(run_robocore, fleet_project)
    assert all(rows[f"r{i}"]["target"] == "v2" for i in range(2, ROBOTS + 1))
    assert {f"r{i}": service_tasks(swarm_hosts, f"r{i}") for i in range(2, ROBOTS + 1)} == before  # untouched
    assert wait_for(lambda: any("hello v2" in line for line in listener_lines(swarm_hosts, 1, PROJECT)), 30)


def test_device_component_is_refused_before_anything_changes(fleet_project: Path, swarm_hosts: RobotFleet,
                                                             run_robocore: RobocoreCli) -> None:
    robot_file = fleet_project / "robot.yaml"
    original = robot_file.read_text()
    before = {f"r{i}": service_tasks(swarm_hosts, f"r{i}") for i in range(1, ROBOTS + 1)}
    data = yaml.safe_load(original)
    data["components"][0]["devices"] = ["/dev/ttyUSB0"]
    robot_file.write_text(yaml.safe_dump(data, sort_keys=False))
    try:
        proc = run_robocore(fleet_project, "fleet", "rollout", "v1", check=False)
    finally:
        robot_file.write_text(original)
    assert proc.returncode == 2, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
    assert len(lines) == 1 and "robot.yaml:" in lines[0] and "devices" in lines[0], proc.stderr
    assert {f"r{i}": service_tasks(swarm_hosts, f"r{i}") for i in range(1, ROBOTS + 1)} == before
