"""A ROS 1 robot in a Swarm fleet (pure plan, and the ROS 1 health probe against a stand-in master).

The services of a noetic robot on the debian base whose only host is arm64: the master (``roscore``) instead of
Fast DDS servers, every node with its robot's ``ROS_MASTER_URI`` and ``ROS_IP``, every image of the arm64 base or
component; the gate's probe is the ROS 1 one, in the arm64 base, on the master's host. The probe script itself runs
here against an XML-RPC stand-in of the master and of the nodes (the standard library's server): a node the master
lists but whose own server does not answer is missing, and a master that does not answer fails the probe with why.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from xmlrpc.server import SimpleXMLRPCServer

import pytest

from robocore import resources
from robocore.config.fleet import parse_fleet_text
from robocore.config.loader import parse_robot_text
from robocore.config.model import Robot
from robocore.plan import naming
from robocore.plan import swarm_services as plan
from robocore.plan.fleet import fleet_instances
from robocore.project import Project

NOETIC = """\
ros_distro: noetic
base: {kind: debian}
hosts:
  - {name: robot, ip: 127.0.0.1, user: root, arch: arm64}
discovery: {servers: [{host: robot}]}
components:
  - {name: talker, folder: components/talker, runs_on: robot, entrypoint: rosrun demo_talker talker}
  - {name: listener, folder: components/listener, runs_on: robot, entrypoint: rosrun demo_listener listener.py}
"""
JAZZY = NOETIC.replace("ros_distro: noetic\nbase: {kind: debian}", "ros_distro: jazzy").replace(
    "arch: arm64", "arch: amd64")
FLEET = """\
manager: {ip: 10.0.0.2}
registry: 10.0.0.2:5000
robots:
  - {name: a1, hosts: {robot: {ip: 10.1.1.1}}}
  - {name: a2, hosts: {robot: {ip: 10.1.2.1}}}
rollout:
  health: {nodes: [/talker, /listener], heard: [/chatter]}
"""
DIGEST = "@sha256:" + "b" * 64
ARM = plan.Release(version="v1",
                   components={"talker": {"arm64": "10.0.0.2:5000/p-talker" + DIGEST},
                               "listener": {"arm64": "10.0.0.2:5000/p-listener" + DIGEST}},
                   base={"arm64": "10.0.0.2:5000/p-base" + DIGEST})
AMD = plan.Release(version="v1", components={c: {"amd64": i["arm64"]} for c, i in ARM.components.items()},
                   base={"amd64": ARM.base["arm64"]})


def fleet_of(text: str, tmp_path: Path) -> tuple[Project, dict[str, Robot]]:
    robot = parse_robot_text(text)
    fleet = parse_fleet_text(FLEET, robot)
    return Project(root=tmp_path / "proj", robot=robot), fleet_instances(robot, fleet)


def test_a_noetic_robot_runs_its_master_and_nodes_as_services_of_its_arm64_images(tmp_path: Path) -> None:
    project, instances = fleet_of(NOETIC, tmp_path)
    found = {s.component: s for s in plan.robot_services(project, "a2", instances["a2"], ARM)}
    assert list(found) == ["discovery-0", "talker", "listener"]
    master = found["discovery-0"]
    assert master.image == ARM.base["arm64"] and master.role == naming.ROLE_DISCOVERY
    assert master.args is not None and "roscore" in master.args
    assert dict(master.environment)["ROS_MASTER_URI"] == "http://10.1.2.1:11311"
    for name in ("talker", "listener"):
        env = dict(found[name].environment)
        assert (env["ROS_MASTER_URI"], env["ROS_IP"]) == ("http://10.1.2.1:11311", "10.1.2.1"), env
        assert "ROS_DISCOVERY_SERVER" not in env and not found[name].configs  # no Fast DDS, no profiles
        assert found[name].image == ARM.components[name]["arm64"]
        assert "node.labels.dev.robocore.arch==arm64" in found[name].constraints
        assert "node.labels.dev.robocore.robot==a2" in found[name].constraints
    # each robot its own master
    other = {s.component: s for s in plan.robot_services(project, "a1", instances["a1"], ARM)}
    assert dict(other["talker"].environment)["ROS_MASTER_URI"] == "http://10.1.1.1:11311"


def test_an_arm64_robot_needs_arm64_images(tmp_path: Path) -> None:
    project, instances = fleet_of(NOETIC, tmp_path)
    with pytest.raises(KeyError, match="arm64"):
        plan.robot_services(project, "a1", instances["a1"], AMD)  # the negative control: amd64 images only


def test_the_probe_of_a_ros1_robot_asks_its_master_from_the_arm64_base(tmp_path: Path) -> None:
    project, instances = fleet_of(NOETIC, tmp_path)
    assert plan.probe_resource(instances["a1"]) == "fleet-probe-ros1"
    check = plan.GateCheck(nodes=("/talker", "/listener"), heard=("/chatter",), timeout=20)
    script = resources.read("fleet-probe-ros1").decode()
    probe = plan.probe_service(project, "a1", instances["a1"], ARM, check, script, "x1")
    assert probe.image == ARM.base["arm64"] and probe.restart == "none"
    assert "node.labels.dev.robocore.arch==arm64" in probe.constraints
    env = dict(probe.environment)
    assert (env["ROS_MASTER_URI"], env["ROS_IP"]) == ("http://10.1.1.1:11311", "10.1.1.1")
    assert probe.args == ("python3", plan.PROBE_SCRIPT, "--timeout", "20", "--node", "/talker", "--node",
                          "/listener", "--heard", "/chatter")
    assert {c.target: c.text for c in probe.configs} == {plan.PROBE_SCRIPT: script}


def test_a_ros2_robot_keeps_the_rclpy_probe(tmp_path: Path) -> None:
    _, instances = fleet_of(JAZZY, tmp_path)
    assert plan.probe_resource(instances["a1"]) == "fleet-probe"
    assert "rclpy" in resources.read("fleet-probe").decode()
    assert "rclpy" not in resources.read("fleet-probe-ros1").decode()


# --- the ROS 1 probe script against a stand-in master --------------------------------------------------------------


@contextlib.contextmanager
def serving(functions: dict[str, object]) -> Iterator[str]:
    """An XML-RPC server on loopback answering ``functions``; its URI."""
    server = SimpleXMLRPCServer(("127.0.0.1", 0), logRequests=False, allow_none=True)
    for name, function in functions.items():
        server.register_function(function, name)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()


@contextlib.contextmanager
def master_of(nodes: dict[str, str]) -> Iterator[str]:
    """A stand-in master knowing ``nodes`` (name -> its XML-RPC URI), each publishing ``/rosout``."""
    state = [[["/rosout", sorted(nodes)]], [], []]
    with serving({"getSystemState": lambda caller: [1, "", state],
                  "lookupNode": lambda caller, name: [1, "", nodes[name]] if name in nodes else [-1, "unknown", ""]},
                 ) as uri:
        yield uri


def probe(tmp_path: Path, master: str, *args: str) -> tuple[int, dict[str, object]]:
    """The probe script run as the probe service runs it (``python3 SCRIPT ...``); its exit code and verdict."""
    script = tmp_path / "fleet-probe.py"
    script.write_bytes(resources.read("fleet-probe-ros1"))
    done = subprocess.run([sys.executable, str(script), *args], capture_output=True, text=True, timeout=60,
                          env={**os.environ, "ROS_MASTER_URI": master}, check=False)
    lines = done.stdout.strip().splitlines()
    assert lines, done.stderr
    return done.returncode, json.loads(lines[-1])


def test_probe_is_ok_when_every_node_is_registered_and_answers(tmp_path: Path) -> None:
    with serving({"getPid": lambda caller: [1, "", 42]}) as talker, master_of({"/talker": talker}) as master:
        code, verdict = probe(tmp_path, master, "--timeout", "5", "--node", "/talker")
    assert code == 0 and verdict["ok"] is True and verdict["missing"] == [] and verdict["error"] == "", verdict
    assert verdict["nodes"] == ["/talker"]


def test_probe_fails_a_node_the_master_lists_but_that_does_not_answer(tmp_path: Path) -> None:
    with serving({"getPid": lambda caller: [1, "", 42]}) as talker:
        dead = talker.replace(talker.rsplit(":", 1)[1], "1/")  # port 1: nothing listens there
        with master_of({"/talker": talker, "/listener": dead}) as master:
            code, verdict = probe(tmp_path, master, "--timeout", "2", "--node", "/talker", "--node", "/listener",
                                  "--node", "/absent")
    assert code == 1 and verdict["ok"] is False, verdict
    assert verdict["missing"] == ["/listener", "/absent"] and verdict["nodes"] == ["/listener", "/talker"], verdict


def test_probe_says_the_master_does_not_answer(tmp_path: Path) -> None:
    with serving({}) as gone:
        pass  # closed: nothing answers at its address any more
    code, verdict = probe(tmp_path, gone, "--timeout", "1", "--node", "/talker")
    assert code == 1 and verdict["ok"] is False and verdict["missing"] == ["/talker"], verdict
    assert str(verdict["error"]).startswith("the ROS master does not answer"), verdict
