"""The pytest plugin as a robot team uses it: pytest runs a project's own graph tests in a subprocess.

Real containers from the project's own images, the project's own discovery server, real rclpy in
the test process. Each claim has its control: a wrong expectation fails (and its report shows the
components' logs), two runs at once see one node of each name each, a killed run's leftovers are
removed by the next, and bring-up failures stop the session once with the cause.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml
from deploy_helpers import output_tails, wait_for

from robocore.plan.testrun import LABEL_OWNER, LABEL_RUN

pytestmark = pytest.mark.docker

GRAPH_TESTS = '''
from std_msgs.msg import String


def test_talker_publishes(robot):
    msg = robot.graph.wait_for_message("/chatter", String)
    assert msg.data.startswith("hello from talker #")


def test_both_nodes_are_in_the_graph(robot):
    robot.graph.wait_for_node("/talker")
    robot.graph.wait_for_node("/listener")


def test_listener_hears_what_the_test_publishes(robot):
    robot.graph.publish("/chatter", String(data="hello from the test"))
    robot.wait_for_log("listener", "I heard: hello from the test")


def test_a_test_stops_the_talker(robot):
    robot.stop("talker")


def test_the_next_test_finds_it_running(robot):
    msg = robot.graph.wait_for_message("/chatter", String, lambda m: m.data.startswith("hello from talker"))
    assert msg.data


def test_exec_runs_in_the_component(robot):
    code, out = robot.exec("talker", ["python3", "-c", "import rclpy; print('rclpy here')"])
    assert code == 0 and "rclpy here" in out, out
'''

Pytest = Callable[..., "subprocess.CompletedProcess[str]"]


def _pytest(project: Path, *args: str, env: dict[str, str] | None = None,
            timeout: float = 600) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q", *args], cwd=project,
                          capture_output=True, text=True, timeout=timeout, env={**os.environ, **(env or {})})


def _run_containers(client: Any, owner_pid: int | None = None) -> list[Any]:
    found = client.containers.list(all=True, filters={"label": LABEL_RUN}, ignore_removed=True)
    if owner_pid is None:
        return list(found)
    return [c for c in found if c.labels.get(LABEL_OWNER, "").split("|")[2:3] == [str(owner_pid)]]


@pytest.fixture
def graph_project(project_copies: Callable[..., Path]) -> Callable[..., Path]:
    """``make(tests, edit=None)``: a ``robocore-it-graph-*`` copy of the built demo project with
    ``tests/graph/test_robot.py`` (conftest's ``project_copies``: what its runs leave is removed)."""

    def make(tests: str = GRAPH_TESTS, edit: Callable[[dict[str, Any]], None] | None = None) -> Path:
        root = project_copies("graph", edit=edit)
        (root / "tests" / "graph").mkdir(parents=True)
        (root / "tests" / "graph" / "test_robot.py").write_text(textwrap.dedent(tests))
        return root

    return make


def test_a_projects_graph_tests_pass(graph_project: Callable[..., Path], docker_client: Any) -> None:
    root = graph_project()
    proc = _pytest(root, "tests/graph")
    assert proc.returncode == 0, output_tails(proc)
    assert "6 passed" in proc.stdout, output_tails(proc)
    leftovers = [c.name for c in _run_containers(docker_client) if c.name.startswith(f"{root.name}-")]
    assert leftovers == [], f"the run left containers behind: {leftovers}"


def test_a_wrong_expectation_fails_and_its_report_shows_the_logs(graph_project: Callable[..., Path]) -> None:
    root = graph_project('''
        from std_msgs.msg import String

        def test_expects_a_wrong_greeting(robot):
            robot.wait_for_log("listener", "I heard: hello from talker #", timeout=30)  # so the report has it
            msg = robot.graph.wait_for_message("/chatter", String)
            assert msg.data == "goodbye from talker"
    ''')
    proc = _pytest(root, "tests/graph")
    assert proc.returncode == 1, output_tails(proc)
    assert "1 failed" in proc.stdout, output_tails(proc)
    assert "robocore: components and graph" in proc.stdout, output_tails(proc)
    assert "--- listener" in proc.stdout and "I heard: hello from talker #" in proc.stdout, output_tails(proc)
    assert "--- talker" in proc.stdout and "Publishing: hello from talker #" in proc.stdout, output_tails(proc)
    assert "/talker" in proc.stdout.split("--- graph", 1)[1], output_tails(proc)


def test_a_message_that_never_comes_names_the_topic_and_publishers(graph_project: Callable[..., Path]) -> None:
    root = graph_project('''
        from std_msgs.msg import String

        def test_waits_for_a_message_nobody_sends(robot):
            robot.graph.wait_for_message("/chatter", String, lambda m: m.data == "never", timeout=2.0)
    ''')
    proc = _pytest(root, "tests/graph")
    assert proc.returncode == 1, output_tails(proc)
    assert "no message matching the predicate on /chatter (String) within 2.0 s" in proc.stdout, output_tails(proc)
    assert "publishers seen: /talker" in proc.stdout, output_tails(proc)
    assert "last message received: std_msgs.msg.String(data='hello from talker #" in proc.stdout, output_tails(proc)


COUNT_NODES = '''
import time

def test_exactly_one_node_of_each_name(robot):
    robot.graph.wait_for_node("/talker")
    robot.graph.wait_for_node("/listener")
    robot.graph.spin(3.0)  # time for another run's nodes to show up, if they could
    names = [(ns.rstrip("/") + "/" + n) for n, ns in robot.graph.node.get_node_names_and_namespaces()]
    assert names.count("/talker") == 1 and names.count("/listener") == 1, names
    own = "/" + robot.graph.node.get_name()
    assert set(names) == {"/talker", "/listener", own}, names  # no other run's probe either
'''


def test_two_runs_of_one_project_at_once_never_see_each_other(graph_project: Callable[..., Path],
                                                              background: Callable[..., Any]) -> None:
    root = graph_project(COUNT_NODES)
    argv = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q", "tests/graph"]
    runs = [background(argv, cwd=root, stderr=subprocess.STDOUT) for _ in range(2)]
    outputs = [run.communicate(timeout=600)[0] for run in runs]
    for run, output in zip(runs, outputs, strict=True):
        assert run.returncode == 0, output[-5000:]
        assert "1 passed" in output, output[-5000:]


def test_the_next_run_removes_what_a_killed_run_left(graph_project: Callable[..., Path], docker_client: Any,
                                                     tmp_path: Path, background: Callable[..., Any]) -> None:
    marker = tmp_path / "up"
    root = graph_project(f'''
        import time
        from pathlib import Path

        def test_hangs(robot):
            Path({str(marker)!r}).write_text("up")
            time.sleep(600)
    ''')
    killed = background([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q", "tests/graph"],
                        cwd=root, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    assert wait_for(marker.exists, 300, interval=0.2), "the first run never came up"
    assert _run_containers(docker_client, killed.pid), "the run's containers are not labelled with their owner"
    killed.send_signal(signal.SIGKILL)
    killed.wait()
    left = _run_containers(docker_client, killed.pid)
    assert left, "a SIGKILLed run left nothing behind: this test no longer proves the clean-up"
    (root / "tests" / "graph" / "test_robot.py").write_text(textwrap.dedent(GRAPH_TESTS))
    proc = _pytest(root, "tests/graph", "-k", "talker_publishes")
    assert proc.returncode == 0, output_tails(proc)
    assert f"removed {len(left)} container(s) left by an earlier run that was killed" in proc.stdout, output_tails(proc)
    assert _run_containers(docker_client, killed.pid) == []
    networks = [n.name for n in docker_client.networks.list(filters={"label": LABEL_OWNER})
                if n.attrs.get("Labels", {}).get(LABEL_OWNER, "").split("|")[2:3] == [str(killed.pid)]]
    assert networks == []


THREE_TESTS = '''
def test_one(robot):
    pass

def test_two(robot):
    pass

def test_three(robot):
    pass
'''


def _assert_stopped_once(proc: subprocess.CompletedProcess[str], cause: str) -> None:
    assert proc.returncode != 0, output_tails(proc)
    assert cause in proc.stdout, output_tails(proc)
    assert "1 error" in proc.stdout and "3 error" not in proc.stdout, output_tails(proc)
    assert "Traceback" not in proc.stdout, output_tails(proc)


def test_a_component_that_dies_at_start_errors_once_with_its_log(graph_project: Callable[..., Path],
                                                                 docker_client: Any) -> None:
    def dying_talker(data: dict[str, Any]) -> None:
        data["components"][0]["entrypoint"] = "sh -c 'echo dying on purpose; exit 3'"

    root = graph_project(THREE_TESTS, edit=dying_talker)
    proc = _pytest(root, "tests/graph")
    _assert_stopped_once(proc, "component talker exited at start (exit code 3)")
    assert "dying on purpose" in proc.stdout, output_tails(proc)
    assert [c.name for c in _run_containers(docker_client) if c.name.startswith(root.name)] == []


def test_an_invalid_robot_yaml_errors_once_in_one_line(graph_project: Callable[..., Path]) -> None:
    root = graph_project(THREE_TESTS)
    data = yaml.safe_load((root / "robot.yaml").read_text())
    data["components"][0]["runs_on"] = "nowhere"
    (root / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    proc = _pytest(root, "tests/graph")
    _assert_stopped_once(proc, "components[0].runs_on: unknown host 'nowhere'")


def test_no_docker_daemon_errors_once_in_one_line(graph_project: Callable[..., Path], tmp_path: Path) -> None:
    root = graph_project(THREE_TESTS)
    proc = _pytest(root, "tests/graph", env={"DOCKER_HOST": f"unix://{tmp_path}/no-docker.sock"})
    _assert_stopped_once(proc, "cannot reach the local Docker daemon")


TWO_HOSTS = '''
from std_msgs.msg import String

def _address(robot, component):
    script = ("import socket; s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM); "
              "s.connect(('192.0.2.1', 9)); print(s.getsockname()[0])")
    code, out = robot.exec(component, ["python3", "-c", script])
    assert code == 0, out
    return out.strip().splitlines()[-1]

def test_hosts_are_separate_namespaces_that_talk_over_the_run_network(robot):
    robot.wait_for_log("listener", "I heard: hello from talker", timeout=20)
    assert _address(robot, "talker") != _address(robot, "listener")
    robot.graph.wait_for_node("/talker")
    robot.graph.wait_for_node("/listener")
'''


def test_a_robot_with_two_hosts_keeps_its_shape(graph_project: Callable[..., Path]) -> None:
    def two_hosts(data: dict[str, Any]) -> None:
        first = data["hosts"][0]
        first.update(ip="192.0.2.9", user="root")
        data["hosts"].append({**first, "name": "arm", "ip": "192.0.2.10"})
        data["components"][1]["runs_on"] = "arm"

    root = graph_project(TWO_HOSTS, edit=two_hosts)
    proc = _pytest(root, "tests/graph")
    assert proc.returncode == 0, output_tails(proc)
    assert "1 passed" in proc.stdout, output_tails(proc)


def test_bring_up_time_is_reported(graph_project: Callable[..., Path], robot_run: Callable[..., Any]) -> None:
    """Not a timing assertion: bring_up records its phases, which bench/graph_tests.py prints."""
    root = graph_project()
    started = time.monotonic()
    run = robot_run(root)
    assert set(run.timings) == {"build", "start", "total"}
    assert 0 < run.timings["total"] <= time.monotonic() - started
