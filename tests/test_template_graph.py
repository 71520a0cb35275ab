"""The template's graph tests (tests/graph), checked without Docker or ROS.

They must use only the documented surface of robocore's pytest plugin and std_msgs, and they
must pass on a robot that behaves like the talker and listener, and fail on one that does not.
Here they run against a simulated robot on a simulated clock: the talker publishes
"hello from talker #N" every 0.5 s and the listener logs "I heard: <text>" for each message.
"""

from __future__ import annotations

import ast
import sys
import types
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import pytest
from template_repo import TEMPLATE

GRAPH_TESTS = TEMPLATE / "tests" / "graph" / "{% if ros_version == 2 %}test_talker_listener.py{% endif %}"
#: The documented API of the `robot` fixture (PLUGIN_API): attributes of robot and of robot.graph.
ROBOT_API = {"graph", "logs", "wait_for_log", "restart", "stop", "start", "kill", "exec", "components", "faults"}
GRAPH_API = {"node", "node_names", "topic_names", "wait_for_message", "publish", "call", "wait_for_node",
             "wait_for_topic", "spin"}
FAULTS_API = {"host_of", "cut_off", "reconnect", "partition", "heal", "limit_link", "unlimit_link", "power_cut",
              "boot", "describe", "clear", "hosts"}


@dataclass
class String:
    data: str = ""


@dataclass
class SimRobot:
    """The talker and listener on a clock that moves only when a test waits."""

    restart_resets_the_count: bool = True
    listener_hears_after_restart: bool = True
    listener_hears_the_test: bool = True
    talker_counts: bool = True
    listener_hears_after_reconnect: bool = True
    nodes: set[str] = field(default_factory=lambda: {"/talker", "/listener"})
    now: float = 0.0
    count: int = 0
    restarted: bool = False
    cut: bool = False
    reconnected: bool = False
    listener_log: list[str] = field(default_factory=list)

    def tick(self) -> str:
        """Half a second passes: the talker publishes and the listener hears it."""
        self.now += 0.5
        self.count += 1 if self.talker_counts else 0
        text = f"hello from talker #{max(self.count, 1)}"
        if (not self.restarted or self.listener_hears_after_restart) and (
                not self.reconnected or self.listener_hears_after_reconnect):
            self.listener_log.append(f"[listener-1] I heard: {text}")
        return text

    # robot.faults (one host: the listener shares it with the talker)
    @property
    def faults(self) -> SimRobot:
        return self

    def host_of(self, component: str) -> str:
        assert component in self.components
        return "devmachine"

    def cut_off(self, host: str) -> None:
        assert host == "devmachine"
        self.cut = True

    def reconnect(self, host: str) -> None:
        assert host == "devmachine" and self.cut
        self.cut, self.reconnected = False, True

    def spin(self, seconds: float) -> None:
        while seconds > 0:
            self.tick()
            seconds -= 0.5

    # the `robot` fixture
    @property
    def graph(self) -> SimRobot:
        return self

    @property
    def components(self) -> list[str]:
        return ["talker", "listener"]

    def logs(self, component: str) -> str:
        assert component == "listener"
        return "\n".join(self.listener_log) + "\n"

    def wait_for_log(self, component: str, text: str, timeout: float = 10.0) -> str:
        deadline = self.now + timeout
        while self.now <= deadline:
            for line in self.logs(component).splitlines():
                if text in line:
                    return line
            self.tick()
        raise AssertionError(f"{component}: no log line with {text!r} in {timeout} s")

    def restart(self, component: str) -> None:
        assert component in self.components
        if component == "talker" and self.restart_resets_the_count:
            self.count = 0
        self.restarted = True

    # robot.graph
    def node_names(self) -> set[str]:
        return set(self.nodes) | {"/robocore_test"}

    def topic_names(self) -> dict[str, list[str]]:
        return {"/chatter": ["std_msgs/msg/String"]}

    def wait_for_node(self, name: str, timeout: float = 10.0) -> None:
        if name not in self.nodes:
            raise AssertionError(f"node {name} not seen in {timeout} s")

    def wait_for_topic(self, name: str, timeout: float = 10.0) -> None:
        if name not in self.topic_names():
            raise AssertionError(f"topic {name} not seen in {timeout} s")

    def wait_for_message(self, topic: str, msg_type: type, predicate: Callable[[Any], bool] | None = None,
                         timeout: float = 10.0) -> Any:
        assert topic == "/chatter" and msg_type is String
        deadline = self.now + timeout
        while self.now < deadline:
            msg = String(data=self.tick())
            if not self.cut and (predicate is None or predicate(msg)):  # a cut-off host is not heard here
                return msg
        raise AssertionError(f"no matching message on {topic} in {timeout} s")

    def publish(self, topic: str, msg: String, timeout: float = 10.0) -> None:
        assert topic == "/chatter"
        if self.listener_hears_the_test:
            self.listener_log.append(f"I heard: {msg.data}")


def load_graph_tests(sim: SimRobot, monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    """The graph test module, with a stand-in std_msgs and its clock bound to the simulation."""
    std_msgs, msg = types.ModuleType("std_msgs"), types.ModuleType("std_msgs.msg")
    msg.String = String  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "std_msgs", std_msgs)
    monkeypatch.setitem(sys.modules, "std_msgs.msg", msg)
    namespace: dict[str, Any] = {"__name__": "test_talker_listener"}
    exec(compile(GRAPH_TESTS.read_text(), str(GRAPH_TESTS), "exec"), namespace)

    def sleep(seconds: float) -> None:
        while seconds > 0:
            sim.tick()
            seconds -= 0.5

    namespace["time"] = types.SimpleNamespace(monotonic=lambda: sim.now, sleep=sleep)
    return namespace


def graph_tests(namespace: dict[str, Any]) -> dict[str, Callable[[Any], None]]:
    return {name: value for name, value in namespace.items() if name.startswith("test_") and callable(value)}


def test_the_graph_tests_are_the_four_behaviours(monkeypatch: pytest.MonkeyPatch) -> None:
    assert sorted(graph_tests(load_graph_tests(SimRobot(), monkeypatch))) == [
        "test_listener_hears_the_talker_again_after_its_host_is_cut_off",
        "test_listener_hears_what_the_test_publishes",
        "test_listener_keeps_hearing_after_the_talker_restarts",
        "test_talker_and_listener_are_in_the_graph",
        "test_talker_publishes_a_growing_count",
    ]


def test_graph_tests_import_only_std_msgs_and_use_only_the_documented_api() -> None:
    tree = ast.parse(GRAPH_TESTS.read_text())
    imported = {alias.name for node in ast.walk(tree) if isinstance(node, ast.Import) for alias in node.names}
    imported |= {node.module or "" for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
    assert {name for name in imported if name.split(".")[0] not in sys.stdlib_module_names} == {"std_msgs.msg"}
    for func in (n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name.startswith("test_")):
        assert [a.arg for a in func.args.args] == ["robot"], func.name
    used_on_robot = {n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute)
                     and isinstance(n.value, ast.Name) and n.value.id == "robot"}
    used_on_graph = {n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute)
                     and isinstance(n.value, ast.Attribute) and n.value.attr == "graph"}
    used_on_faults = {n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute)
                      and isinstance(n.value, ast.Attribute) and n.value.attr == "faults"}
    assert used_on_robot <= ROBOT_API and used_on_graph <= GRAPH_API and used_on_faults <= FAULTS_API
    assert {"graph", "logs", "wait_for_log", "restart"} <= used_on_robot
    assert not (GRAPH_TESTS.parent / "conftest.py").exists()  # the plugin's entry point brings the fixture


@pytest.mark.parametrize("name", ["test_talker_and_listener_are_in_the_graph", "test_talker_publishes_a_growing_count",
                                  "test_listener_hears_what_the_test_publishes",
                                  "test_listener_keeps_hearing_after_the_talker_restarts",
                                  "test_listener_hears_the_talker_again_after_its_host_is_cut_off"])
def test_each_graph_test_passes_on_a_working_robot(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    sim = SimRobot()
    graph_tests(load_graph_tests(sim, monkeypatch))[name](sim)


@pytest.mark.parametrize(("broken", "name", "message"), [
    ({"nodes": {"/talker"}}, "test_talker_and_listener_are_in_the_graph", "/listener"),
    ({"talker_counts": False}, "test_talker_publishes_a_growing_count", "no matching message"),
    ({"listener_hears_the_test": False}, "test_listener_hears_what_the_test_publishes", "I heard: hello from the"),
    ({"listener_hears_after_restart": False}, "test_listener_keeps_hearing_after_the_talker_restarts",
     "did not hear"),
    ({"restart_resets_the_count": False}, "test_listener_keeps_hearing_after_the_talker_restarts",
     "no matching message"),
    ({"listener_hears_after_reconnect": False}, "test_listener_hears_the_talker_again_after_its_host_is_cut_off",
     "did not hear"),
])
def test_each_graph_test_fails_on_a_robot_without_its_behaviour(broken: dict[str, Any], name: str, message: str,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    sim = SimRobot(**broken)
    with pytest.raises(AssertionError, match=message):
        graph_tests(load_graph_tests(sim, monkeypatch))[name](sim)


def test_the_restart_test_does_not_mistake_the_listeners_old_lines_for_new_ones(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Before the restart the listener already printed every text the new talker sends first."""
    sim = SimRobot(listener_hears_after_restart=False)
    test = graph_tests(load_graph_tests(sim, monkeypatch))["test_listener_keeps_hearing_after_the_talker_restarts"]
    with pytest.raises(AssertionError):
        test(sim)
    assert any(line.endswith("I heard: hello from talker #1") for line in sim.listener_log)


def test_the_fault_calls_the_template_may_use_exist() -> None:
    from robocore.testing.bringup import RobotUnderTest
    from robocore.testing.faults import Faults

    assert set(dir(Faults)) >= FAULTS_API
    assert ROBOT_API - {"components", "graph"} <= set(dir(RobotUnderTest))
