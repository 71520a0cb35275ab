"""A ROS 1 robot: the template's noetic project on the debian base (Debian 12's own ROS 1 packages).

- one host: ``prepare-base stage build run``; the rospy listener hears the roscpp talker's
  ``demo_msgs/Greeting`` through the ROS master, ``status`` lists both nodes through the master;
  a probe pointed at a port with no master hears nothing (negative control) while the same probe
  pointed at the robot's master hears the talker;
- the fleet's update-lock probe for ROS 1, run as its Swarm task runs it, hears a node's latched ``true`` on
  ``/robocore/update_lock`` through the master (locked), a latched ``false`` (free), and no publisher (free, at once);
- the master stopped: ``status`` says so, connected nodes keep talking, a new node hears nothing;
  ``run`` starts the master and restarts the nodes (they register only at start), and the graph is
  whole again; the master restarted behind robocore's back (``docker restart``): ``status`` names the
  nodes it does not know, and a new node hears nothing until ``run`` restarts them;
- the talker back in place (SIGKILLed and started again; crashed and restarted by its policy) is heard within
  2 s of its start;
- a one-line edit of the C++ talker goes through ``build`` and ``run`` and is heard;
- the project's own ``nox -s validate build unit graph``: gtest and pytest package tests, then the ROS 1 graph tests
  through robocore's pytest plugin;
- ``robot.faults`` (the pytest plugin's bring-up, two robot hosts): a cut-off host's TCPROS traffic stops and
  resumes on reconnection;
- two Docker-in-Docker hosts over ssh: the talker and the master on robot-a, the listener on robot-b;
  robot-b alone hears nothing (no master, no talker), then robot-b hears robot-a's talker; after the
  master stopped, ``run`` restarts it and the nodes of both hosts, and robot-b hears again; after the
  master restarted behind robocore's back, ``run`` restarts the nodes that started before it.
"""

from __future__ import annotations

import json
import shutil
import statistics
import tempfile
import time
import xmlrpc.client
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import lanes
import pytest
import yaml
from deploy_helpers import (
    HEARD,
    free_tcp_port,
    log_lines,
    output_tails,
    remove_project_containers,
    run_nox,
    wait_for,
)
from ways_back import Pair, in_place_ways

if TYPE_CHECKING:
    from conftest import RobocoreCli
    from robot_host.hosts import RobotFleet

pytestmark = pytest.mark.docker

NAME = "robocore-it-noetic"
TALKER_TEXT = "hello from talker #"
#: Rounds of each way back in place, and the bound on their median (seconds from the talker's start to heard).
WAY_ROUNDS = 3
BACK_WITHIN = 2.0


def _init(parent: Path, run_robocore: RobocoreCli, *, port: int) -> Path:
    """``robocore init --distro noetic --base debian`` in ``parent``, its master on ``port``."""
    root = parent / NAME
    run_robocore(None, "init", str(root), "--defaults", "--distro", "noetic", "--base", "debian")
    data = yaml.safe_load((root / "robot.yaml").read_text())
    data["discovery"] = {"servers": [{"host": data["hosts"][0]["name"], "port": port}]}
    (root / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    return root


@pytest.fixture(scope="module")
def noetic(docker_client: Any, run_robocore: RobocoreCli) -> Iterator[Path]:
    """The template's noetic project on the debian base, after prepare-base, stage and build."""
    parent = Path(tempfile.mkdtemp(prefix="robocore-it-"))
    root = _init(parent, run_robocore, port=free_tcp_port())
    for step in ("prepare-base", "stage", "build"):
        run_robocore(root, step, "--quiet")
    yield root
    remove_project_containers(docker_client, NAME)
    shutil.rmtree(parent, ignore_errors=True)


def _container(docker_client: Any, component: str) -> Any:
    return docker_client.containers.get(f"{NAME}-{component}")


def _heard_since(docker_client: Any, since: float, needle: str = TALKER_TEXT) -> list[str]:
    return [line for line in log_lines(_container(docker_client, "listener"), HEARD, since=since) if needle in line]


def _master_uri(root: Path) -> str:
    data = yaml.safe_load((root / "robot.yaml").read_text())
    return f"http://127.0.0.1:{data['discovery']['servers'][0]['port']}"


def _probe(docker_client: Any, tracked: list[Any], master_uri: str, seconds: int = 15) -> str:
    """A new node in the base image (demo_msgs built in): ``rostopic echo -n 1 /chatter`` against ``master_uri``,
    for at most ``seconds``; what it printed."""
    container = docker_client.containers.run(
        f"{NAME}-base:latest", ["timeout", str(seconds), "rostopic", "echo", "-n", "1", "/chatter"],
        environment={"ROS_MASTER_URI": master_uri, "ROS_IP": "127.0.0.1", "PYTHONUNBUFFERED": "1"},
        network_mode="host", detach=True)
    tracked.append(container)
    container.wait(timeout=seconds + 30)
    return str(container.logs().decode(errors="replace"))


def _status(run_robocore: RobocoreCli, root: Path) -> dict[str, Any]:
    return dict(json.loads(run_robocore(root, "status", "--json", "--nodes", check=False).stdout))


def _graph(status: dict[str, Any]) -> dict[str, Any]:
    [graph] = [r for r in status["results"] if r["kind"] == "ros_graph"]
    return dict(graph)


def _run_restarts_nodes(run_robocore: RobocoreCli, root: Path, master_verb: str, reason: str) -> None:
    """``run``: the master gets ``master_verb``, and the talker and the listener (wherever they run) are
    replaced for ``reason``."""
    done = json.loads(run_robocore(root, "run", "--json").stdout)
    verbs = {a["name"]: (a["verb"], a["reason"]) for r in done["results"] for a in r["actions"]}
    assert verbs[f"{NAME}-discovery-0"][0] == master_verb, verbs
    for component in ("talker", "listener"):
        verb, why = verbs[f"{NAME}-{component}"]
        assert verb == "replace" and reason in why, verbs


def test_cpp_talker_heard_by_rospy_listener_through_the_master(noetic: Path, run_robocore: RobocoreCli,
                                                                docker_client: Any,
                                                                tracked_containers: list[Any]) -> None:
    started = time.time()
    run_robocore(noetic, "run", "--quiet")
    assert wait_for(lambda: _heard_since(docker_client, started), 60, 1), \
        "the rospy listener never heard the C++ talker"
    graph = _graph(_status(run_robocore, noetic))
    assert {"/talker", "/listener", "/rosout"} <= set(graph["nodes"] or []), graph
    # negative control: the same probe, pointed at a port with no master, hears nothing
    lost = _probe(docker_client, tracked_containers, f"http://127.0.0.1:{free_tcp_port()}", seconds=10)
    assert TALKER_TEXT not in lost and "Unable to communicate with master" in lost, lost
    found = _probe(docker_client, tracked_containers, _master_uri(noetic))
    assert TALKER_TEXT in found, found
    # the live container's shell has ROS 1 sourced
    topics = run_robocore(noetic, "connect", "--component", "talker", "--cmd", "rostopic list")
    assert "/chatter" in topics.stdout, topics.stdout


def _lock_probe(docker_client: Any, tracked: list[Any], master_uri: str) -> tuple[int, dict[str, Any]]:
    """robocore's ROS 1 update-lock probe (:mod:`robocore.plan.fleet_lock`), run in the base image as its Swarm task
    runs it, against ``master_uri``: its exit code and its answer."""
    from robocore import resources
    from robocore.plan import fleet_lock

    script = resources.read("fleet-lock-probe-ros1").decode()
    container = docker_client.containers.run(
        f"{NAME}-base:latest", ["python3", "-c", script, "--topic", fleet_lock.LOCK_TOPIC, "--wait", "5"],
        environment={"ROS_MASTER_URI": master_uri, "ROS_IP": "127.0.0.1"}, network_mode="host", detach=True)
    tracked.append(container)
    code = container.wait(timeout=60)["StatusCode"]
    lines = container.logs(stderr=False).decode(errors="replace").strip().splitlines()
    assert lines, container.logs().decode(errors="replace")
    return code, dict(json.loads(lines[-1]))


def test_the_update_lock_probe_hears_a_latched_lock_through_the_master(noetic: Path, run_robocore: RobocoreCli,
                                                                      docker_client: Any,
                                                                      tracked_containers: list[Any]) -> None:
    """A node of the robot holds its update lock (``/robocore/update_lock``, std_msgs/Bool, latched): the probe
    ``fleet rollout`` runs on the robot before it touches it asks the master for the topic's publishers, subscribes
    with rospy and hears ``true`` (locked, exit 1); a latched ``false`` is no lock (exit 0); with no publisher it
    answers at once (the control: "locked" comes from what it heard)."""
    from robocore.plan import fleet_lock

    run_robocore(noetic, "run", "--quiet")
    master = _master_uri(noetic)
    assert _lock_probe(docker_client, tracked_containers, master) == (
        0, {"locked": False, "publishers": 0, "heard": 0, "error": ""})
    for value, code in (("true", 1), ("false", 0)):
        publisher = docker_client.containers.run(
            f"{NAME}-base:latest", ["rostopic", "pub", "-l", fleet_lock.LOCK_TOPIC, "std_msgs/Bool", f"data: {value}"],
            environment={"ROS_MASTER_URI": master, "ROS_IP": "127.0.0.1"}, network_mode="host", detach=True)
        tracked_containers.append(publisher)
        try:
            def registered() -> bool:
                answer, _, state = xmlrpc.client.ServerProxy(master).getSystemState("/it")
                return answer == 1 and any(topic == fleet_lock.LOCK_TOPIC for topic, _ in state[0])

            assert wait_for(registered, 30, 0.2), publisher.logs().decode(errors="replace")
            answer = _lock_probe(docker_client, tracked_containers, master)
            assert answer == (code, {"locked": value == "true", "publishers": 1, "heard": 1, "error": ""}), answer
        finally:
            publisher.stop(timeout=10)  # SIGTERM: rostopic unregisters from the master


def test_stopped_master_keeps_connections_and_run_brings_the_graph_back(noetic: Path, run_robocore: RobocoreCli,
                                                                        docker_client: Any,
                                                                        tracked_containers: list[Any]) -> None:
    run_robocore(noetic, "run", "--quiet")
    assert wait_for(lambda: _heard_since(docker_client, time.time() - 5), 60, 1)
    docker_client.containers.get(f"{NAME}-discovery-0").stop(timeout=5)
    stopped = time.time()
    status = _status(run_robocore, noetic)
    rows = {r["component"]: r["state"] for r in status["results"] if r["kind"] == "container"}
    assert rows["discovery-0"] == "exited" and rows["talker"] == rows["listener"] == "running", rows
    graph = _graph(status)
    assert graph["nodes"] is None and "the ROS master is down" in graph["via"], graph
    # connected nodes keep exchanging messages; a new node cannot join
    assert wait_for(lambda: _heard_since(docker_client, stopped + 1), 30, 1), \
        "the connected listener stopped hearing when the master stopped"
    assert TALKER_TEXT not in _probe(docker_client, tracked_containers, _master_uri(noetic), seconds=10)
    # run starts the master and restarts the nodes, which register only when they start
    _run_restarts_nodes(run_robocore, noetic, "start", "register")
    restarted = time.time()
    assert wait_for(lambda: _heard_since(docker_client, restarted), 60, 1)
    graph = _graph(_status(run_robocore, noetic))
    assert {"/talker", "/listener"} <= set(graph["nodes"] or []), graph
    again = json.loads(run_robocore(noetic, "run", "--json").stdout)
    assert {a["verb"] for r in again["results"] for a in r["actions"]} == {"keep"}, again

    # the master restarted behind robocore's back (as Docker's restart policy does after a crash): it runs,
    # but knows no node; run keeps it and restarts the nodes that started before it
    docker_client.containers.get(f"{NAME}-discovery-0").restart(timeout=5)
    assert TALKER_TEXT not in _probe(docker_client, tracked_containers, _master_uri(noetic), seconds=10)
    graph = _graph(_status(run_robocore, noetic))
    assert sorted(graph["not_registered"]) == ["listener", "talker"], graph
    assert not {"/talker", "/listener"} & set(graph["nodes"] or []), graph
    _run_restarts_nodes(run_robocore, noetic, "keep", "before the discovery server's last start")
    assert TALKER_TEXT in _probe(docker_client, tracked_containers, _master_uri(noetic))
    assert _graph(_status(run_robocore, noetic))["not_registered"] == []


@pytest.mark.quiet
def test_a_ros1_talker_back_in_place_is_heard_within_2_s(noetic: Path, run_robocore: RobocoreCli,
                                                         docker_client: Any) -> None:
    """The roscpp talker deployed by ``run`` (restart policy ``unless-stopped``) SIGKILLed and started again in
    place, then crashed (its process killed from outside Docker) and started again by its policy: each time it
    registers with the master again and the rospy listener hears it within 2 s of its start (median of 3,
    :mod:`ways_back`)."""
    pair = Pair(docker_client, f"{NAME}-talker", f"{NAME}-listener")
    with lanes.untimed():  # the bring-up times nothing: the other lanes may work meanwhile
        run_robocore(noetic, "run", "--quiet")
        pair.wait_heard(60)

    killed, crashed = in_place_ways(pair, "ROS 1", WAY_ROUNDS)
    assert statistics.median(killed) < BACK_WITHIN, killed
    assert statistics.median(crashed) < BACK_WITHIN, crashed


def test_one_line_cpp_edit_is_built_and_heard(noetic: Path, run_robocore: RobocoreCli, docker_client: Any) -> None:
    [code] = (noetic / "components" / "talker").rglob("greeting.h")  # the text talker.cpp publishes
    original = code.read_text()
    try:
        code.write_text(original.replace(f'"{TALKER_TEXT}"', '"edited talker #"'))
        run_robocore(noetic, "build", "--component", "talker", "--quiet")
        since = time.time()
        run_robocore(noetic, "run", "--quiet")
        assert wait_for(lambda: _heard_since(docker_client, since, "edited talker #"), 60, 1), \
            "the edited C++ talker was never heard"
    finally:
        code.write_text(original)
        run_robocore(noetic, "build", "--component", "talker", "--quiet")


def test_the_noetic_projects_own_nox_sessions_pass(noetic: Path) -> None:
    """The project's gtest and pytest package tests through ``robocore test``, then its ROS 1 graph tests
    through robocore's pytest plugin (an isolated bring-up with its own master)."""
    proc = run_nox(noetic, "validate", "build", "unit", "graph")
    text = proc.stdout + proc.stderr
    assert proc.returncode == 0, output_tails(proc)
    for session in ("validate", "build", "unit", "graph"):
        assert f"Session {session} was successful" in text, output_tails(proc)
    assert "demo_talker" in text and "demo_listener" in text, output_tails(proc)  # both packages' tests ran


@pytest.mark.quiet
def test_faults_on_a_two_host_ros1_robot_cut_off_and_reconnect(noetic: Path, tmp_path: Path) -> None:
    """``robot.faults`` on ROS 1: the pytest plugin's bring-up of a copy of the noetic project on two robot hosts
    (talker and master on ``main``, listener on ``arm``). Cutting ``main`` off stops the listener's TCPROS
    traffic; reconnecting it lets the same connection resume (no new registration: the master is on ``main``
    too). Control: without the fault the listener hears the talker (2 Hz) all through the same window."""
    from robocore.testing import bring_up

    root = tmp_path / NAME
    with lanes.untimed():  # the copy and the bring-up time nothing: the other lanes may work meanwhile
        shutil.copytree(noetic, root, symlinks=True, ignore=shutil.ignore_patterns("compose", "test-runs"))
        data = yaml.safe_load((root / "robot.yaml").read_text())
        first = data["hosts"][0]
        data["hosts"] = [{**first, "name": "main", "ip": "192.0.2.9"},
                         {**first, "name": "arm", "ip": "192.0.2.10"}]
        for comp in data["components"]:
            comp["runs_on"] = "arm" if comp["name"] == "listener" else "main"
        data["discovery"] = {"servers": [{"host": "main", "port": 11311}]}
        (root / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
        robot = bring_up(root, graph=False)
    try:
        def heard() -> int:
            return sum(TALKER_TEXT in line for line in robot.logs("listener").splitlines() if HEARD in line)

        with lanes.untimed():
            assert wait_for(heard, 60, 0.5), "the listener on arm never heard the talker on main"
        before = heard()
        time.sleep(3.0)
        assert heard() - before >= 4, "control: traffic stopped without a fault"
        robot.faults.cut_off("main")
        time.sleep(0.5)
        before = heard()
        time.sleep(3.0)
        assert heard() == before, "the listener heard a cut-off host"
        assert robot.faults.describe() == ["host main cut off from the network"]
        robot.faults.reconnect("main")
        reconnected = time.monotonic()
        assert wait_for(lambda: heard() > before, 30, 0.1), "traffic did not resume after the reconnection"
        print(f"FIGURE ros1_reconnect_to_heard_s {time.monotonic() - reconnected:.2f}")
        assert robot.undo_faults() == []
    finally:
        robot.close()


# --------------------------------------------------------------------------- two hosts


@pytest.fixture(scope="module")
def noetic_fleet(robot_fleets: Callable[..., RobotFleet], noetic: Path, run_robocore: RobocoreCli,
                 tmp_path_factory: pytest.TempPathFactory) -> tuple[RobotFleet, Path]:
    """Two robot hosts and a copy of the noetic project: talker and master on robot-a, listener on robot-b."""
    fleet = robot_fleets(2)
    root = tmp_path_factory.mktemp("noetic-fleet") / NAME
    shutil.copytree(noetic, root, symlinks=True, ignore=shutil.ignore_patterns("compose"))
    data = yaml.safe_load((root / "robot.yaml").read_text())
    data["hosts"] = [{"name": n, "ip": h.ip, "user": "root", "arch": "amd64"}
                     for n, h in zip(["robot-a", "robot-b"], fleet.hosts, strict=True)]
    data["discovery"] = {"servers": [{"host": "robot-a"}]}
    for comp in data["components"]:
        comp["runs_on"] = "robot-a" if comp["name"] == "talker" else "robot-b"
    (root / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    for step in ("prepare-base", "stage", "build", "sync"):
        run_robocore(root, step, "--quiet")
    return fleet, root


def test_two_hosts_one_ros1_graph(noetic_fleet: tuple[RobotFleet, Path], run_robocore: RobocoreCli) -> None:
    fleet, root = noetic_fleet
    listener = f"{NAME}-listener"

    def heard() -> list[str]:
        lines = log_lines(fleet.client(1).containers.get(listener), HEARD)
        return [line for line in lines if TALKER_TEXT in line]

    # robot-b alone: no master, no talker, nothing heard (negative control)
    run_robocore(root, "run", "--host", "robot-b", "--quiet")
    time.sleep(8)
    assert heard() == []
    run_robocore(root, "run", "--host", "robot-a", "--quiet")
    assert wait_for(heard, 90, 1), "the listener on robot-b never heard the talker on robot-a"
    env = fleet.client(1).containers.get(listener).attrs["Config"]["Env"]
    assert f"ROS_IP={fleet.hosts[1].ip}" in env and f"ROS_MASTER_URI=http://{fleet.hosts[0].ip}:11311" in env, env
    graph = _graph(_status(run_robocore, root))
    assert {"/talker", "/listener"} <= set(graph["nodes"] or []), graph

    # the master stopped behind robocore's back on robot-a: run starts it first, then restarts the nodes on
    # both hosts (they register only when they start), and the graph is whole again
    master = fleet.client(0).containers.get(f"{NAME}-discovery-0")
    master.stop(timeout=5)
    _run_restarts_nodes(run_robocore, root, "start", "register")
    assert wait_for(heard, 90, 1), "robot-b's listener never heard the talker again after the master restarted"
    graph = _graph(_status(run_robocore, root))
    assert {"/talker", "/listener"} <= set(graph["nodes"] or []), graph
    # restarted behind robocore's back on robot-a: run reads its start there and restarts robot-b's listener
    master.restart(timeout=5)
    _run_restarts_nodes(run_robocore, root, "keep", "before the discovery server's last start")
    assert wait_for(heard, 90, 1), "robot-b's listener never heard the talker after the master's restart"
