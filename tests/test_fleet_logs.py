"""``fleet logs ROBOT`` and ``fleet connect ROBOT COMPONENT``: their command lines, the names they accept (a bad one is
one line listing what exists, exit 2), what they read through the manager (faked here: the Swarm suite runs them
against a real swarm) and the shell's argv on the robot's host."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from robocore.adapters import ssh
from robocore.cli import CommandLineError, fleet_task, main
from robocore.commands import fleet_connect, fleet_logs
from robocore.config.fleet import parse_fleet_text
from robocore.config.loader import parse_robot_text
from robocore.errors import UsageError
from robocore.plan import swarm_services as plan
from robocore.plan.fleet import fleet_instances
from robocore.plan.fleet_parts import Part, robot_parts

ROBOT = """\
ros_distro: jazzy
ros_domain_id: 7
hosts:
  - {name: main, ip: 192.0.2.1, user: root}
  - {name: aux, ip: 192.0.2.2, user: root}
discovery: {servers: [{host: main, port: 11811}]}
components:
  - {name: talker, folder: components/talker, runs_on: main, entrypoint: ros2 run demo_talker talker}
  - {name: listener, folder: components/listener, runs_on: aux}
"""
FLEET = """\
manager: {ip: 10.0.0.2, user: root}
registry: 10.0.0.2:5000
robots:
  - {name: r1, hosts: {main: {ip: 10.1.1.1}, aux: {ip: 10.1.1.2}}}
  - {name: r2, hosts: {main: {ip: 10.1.2.1}, aux: {ip: 10.1.2.2}}}
"""


@pytest.mark.parametrize(("words", "flags"), [
    (["logs", "r1"], ["--robot", "r1"]),
    (["logs", "r1", "--component", "talker", "--follow"], ["--robot", "r1", "--component", "talker", "--follow"]),
    (["logs", "--component", "talker", "r1"], ["--component", "talker", "--robot", "r1"]),  # a flag's value
    (["connect", "r1", "talker"], ["--robot", "r1", "--component", "talker"]),
    (["connect", "--", "-r", "talker"], ["--robot", "-r", "--component", "talker"]),
    (["rollout", "v2", "--json"], ["--version", "v2", "--json"]),  # as before
])
def test_fleet_words_become_the_tasks_flags(words: list[str], flags: list[str]) -> None:
    assert fleet_task(["fleet", *words]) == ["fleet", "--verb", words[0], *flags]


def test_connect_takes_one_robot_and_one_component() -> None:
    with pytest.raises(CommandLineError, match="one robot and one component"):
        fleet_task(["fleet", "connect", "r1", "talker", "listener"])


def instances() -> dict[str, Any]:
    robot = parse_robot_text(ROBOT)
    return dict(fleet_instances(robot, parse_fleet_text(FLEET, robot)))


def test_a_robots_parts_are_its_servers_then_its_components() -> None:
    assert robot_parts("p", instances(), "r2") == [Part("discovery-0", "main", "p-r2-discovery-0"),
                                                   Part("talker", "main", "p-r2-talker"),
                                                   Part("listener", "aux", "p-r2-listener")]
    assert robot_parts("p", instances(), "r1", "listener") == [Part("listener", "aux", "p-r1-listener")]


def test_a_bad_name_is_one_line_listing_what_exists() -> None:
    with pytest.raises(UsageError) as robot:
        robot_parts("p", instances(), "r9")
    assert robot.value.lines() == ["no robot 'r9' in fleet.yaml (its robots: r1, r2)"]
    with pytest.raises(UsageError) as component:
        robot_parts("p", instances(), "r1", "talk")
    assert component.value.lines() == ["robot r1 has no component 'talk' (its components: discovery-0, talker, "
                                       "listener)"]


@pytest.fixture
def project(tmp_path: Path) -> Path:
    root = tmp_path / "proj"
    for component in ("talker", "listener"):
        (root / "components" / component).mkdir(parents=True)
    (root / "robot.yaml").write_text(ROBOT)
    (root / "fleet.yaml").write_text(FLEET)
    return root


def run(root: Path, *args: str, capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """``robocore -p ROOT fleet ARGS``: exit code, stdout, stderr."""
    code: Any = 0
    try:
        main(["-p", str(root), "fleet", *args])
    except SystemExit as done:
        code = done.code
    out = capsys.readouterr()
    return int(code or 0), out.out, out.err


@pytest.mark.parametrize(("args", "message"), [
    (["logs", "r9"], "error: no robot 'r9' in fleet.yaml (its robots: r1, r2)"),
    (["logs", "r1", "--component", "nope"], "error: robot r1 has no component 'nope' (its components: discovery-0, "
                                           "talker, listener)"),
    (["connect", "r2", "nope"], "error: robot r2 has no component 'nope'"),
    (["connect", "r9", "talker"], "error: no robot 'r9' in fleet.yaml"),
    (["logs"], "error: fleet logs ROBOT [--component C] [--follow]: name one robot (got none)"),
    (["connect", "r1"], "error: fleet connect ROBOT COMPONENT: name the component (got r1)"),
    (["status", "--follow"], "error: --component and --follow are fleet logs', not fleet status's"),
    (["connect", "r1", "talker", "--follow"], "error: --follow is fleet logs', not fleet connect's"),
])
def test_bad_names_and_flags_are_one_line_and_exit_2(project: Path, args: list[str], message: str,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run(project, *args, "--dry-run", capsys=capsys)
    assert code == 2 and err.strip().startswith(message) and len(err.strip().splitlines()) == 1, err


def test_dry_runs_say_what_is_read_and_run_and_contact_nothing(project: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(project, "logs", "r1", "--dry-run", capsys=capsys)
    assert code == 0 and "manager 10.0.0.2" in out and "not contacted" in out
    assert [line.split()[6] for line in out.splitlines()[1:]] == ["proj-r1-discovery-0", "proj-r1-talker",
                                                                  "proj-r1-listener"], out
    code, out, _ = run(project, "connect", "r2", "talker", "--dry-run", capsys=capsys)
    shell = out.splitlines()[1]
    assert code == 0 and "service proj-r2-talker" in shell, out
    assert "ssh -T" in shell and "root@10.1.2.1" in shell, shell  # the robot host's own address from fleet.yaml
    assert "'docker exec -i --env=" in shell and " -- TASK_CONTAINER /robocore/entrypoint.sh sh -c " in shell, shell


class FakeManager:
    """What fleet logs and connect ask the manager: its nodes, a service's logs (in chunks cut mid-line), its
    running task."""

    def __init__(self, project: str, *, aux_state: str = "ready") -> None:
        self.read: list[tuple[str, bool, str]] = []
        self.closed = False
        nodes = [(f"n-{r}-{h}", plan.node_labels(project, r, h, "amd64"), "ready" if h == "main" else aux_state)
                 for r in ("r1", "r2") for h in ("main", "aux")]
        manager = self

        class Nodes:
            def list(self) -> list[Any]:
                return [type("Node", (), {"attrs": {"ID": i, "Spec": {"Labels": labels, "Availability": "active"},
                                                    "Status": {"State": state}}})() for i, labels, state in nodes]

        class Api:
            def service_logs(self, service: str, **kwargs: Any) -> Iterator[bytes]:
                manager.read.append((service, kwargs["follow"], kwargs["tail"]))
                yield from (b"[INFO] hel", f"lo from {service}\n[INFO] sec".encode(), b"ond\n")

            def tasks(self, filters: dict[str, str]) -> list[dict[str, Any]]:
                if filters != {"service": f"{project}-r1-talker", "desired-state": "running"}:
                    return []
                status = {"State": "running", "ContainerStatus": {"ContainerID": "c0ffee"}}
                return [{"NodeID": "n-r1-main", "Status": status,
                         "Spec": {"ContainerSpec": {"Command": ["/robocore/entrypoint.sh"]}}}]

        self.nodes = Nodes()
        self.api = Api()

    def close(self) -> None:
        self.closed = True


def test_logs_are_read_through_the_manager_each_line_behind_its_component(
        project: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    manager = FakeManager("proj")
    monkeypatch.setattr(fleet_logs, "_client", lambda fleet: manager)
    code, out, err = run(project, "logs", "r1", capsys=capsys)
    assert code == 0, err
    assert out.splitlines() == ["discovery-0 | [INFO] hello from proj-r1-discovery-0", "discovery-0 | [INFO] second",
                                "talker      | [INFO] hello from proj-r1-talker", "talker      | [INFO] second",
                                "listener    | [INFO] hello from proj-r1-listener", "listener    | [INFO] second"]
    assert manager.read == [(f"proj-r1-{p}", False, "100") for p in ("discovery-0", "talker", "listener")]
    assert manager.closed
    code, out, _ = run(project, "logs", "r1", "--component", "listener", "--json", capsys=capsys)
    lines = [r["line"] for r in json.loads(out)["results"]]
    assert code == 0 and lines == ["[INFO] hello from proj-r1-listener", "[INFO] second"], out
    manager.read.clear()  # --follow: the live streams merged (each ends here when the fake's chunks do)
    code, out, _ = run(project, "logs", "r1", "--component", "talker", "--follow", capsys=capsys)
    assert code == 0 and out.splitlines() == ["talker | [INFO] hello from proj-r1-talker", "talker | [INFO] second"]
    assert manager.read == [("proj-r1-talker", True, "100")]


def test_a_host_whose_node_is_down_is_named_and_skipped(project: Path, monkeypatch: pytest.MonkeyPatch,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    manager = FakeManager("proj", aux_state="down")
    monkeypatch.setattr(fleet_logs, "_client", lambda fleet: manager)
    code, out, err = run(project, "logs", "r1", capsys=capsys)
    assert code == 0 and "host aux is offline" in err and "listener" in err, err
    assert "listener" not in out and "talker      | [INFO] second" in out, out
    assert [s for s, _, _ in manager.read] == ["proj-r1-discovery-0", "proj-r1-talker"]  # the manager was not asked
    code, _, err = run(project, "logs", "r1", "--component", "listener", capsys=capsys)
    assert code == 7 and "robot r1 is offline: no logs of it can be read through the manager" in err, err


def test_connect_enters_the_running_tasks_container_on_the_robots_host(
        project: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    calls: list[list[str]] = []
    monkeypatch.setattr(fleet_connect, "manager_client", lambda fleet: FakeManager("proj"))
    monkeypatch.setattr(fleet_connect.subprocess, "call", lambda argv, env: calls.append(argv) or 3)
    monkeypatch.setattr(ssh, "require_ssh", lambda: None)
    monkeypatch.setattr(ssh, "ensure_control_dir", lambda: None)
    code, _, err = run(project, "connect", "r1", "talker", capsys=capsys)
    assert code == 3, err  # the shell's own exit code
    (argv,) = calls
    assert argv[:2] == ["ssh", "-T"] and argv[argv.index("--") + 1] == "root@10.1.1.1", argv
    remote = argv[-1]
    assert remote.startswith("docker exec -i --env=") and " -- c0ffee /robocore/entrypoint.sh sh -c " in remote, remote
    assert "--env=ROS_DISCOVERY_SERVER=10.1.1.1:11811" in remote, remote  # a super client of r1's own server
    code, _, err = run(project, "connect", "r2", "talker", capsys=capsys)
    assert code == 2 and "r2's talker runs no task on its host main now" in err, err



def test_a_dry_run_of_a_rollout_shows_the_waves_before_the_release_exists(project: Path,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """Before ``release --fleet --tag v2``: the waves and the manager, and that the release's images are not checked;
    the rollout itself still refuses, saying how to make the release."""
    code, out, _ = run(project, "rollout", "v2", "--dry-run", capsys=capsys)
    assert code == 0 and "manager 10.0.0.2" in out and "wave rest: r1, r2" in out, out
    assert "release v2 is not made yet (robocore release --fleet --tag v2): its images are not checked" in out
    code, _, err = run(project, "rollout", "v2", capsys=capsys)
    assert code == 2 and "error: no fleet release v2" in err and "release --fleet --tag v2" in err, err
