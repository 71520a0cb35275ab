"""`robocore run/down/status/logs/connect` on this machine's Docker, through the CLI, on copies of the demo project.

Controls: idempotency is checked by container IDs (a recreated container has a new ID), the changed
component is the only one with a new ID; an unreachable host is reported by name while the
reachable one is deployed; a missing install tree is refused before anything starts; a discovery server's
graceful stop is set against the same server without Docker's init.
"""

from __future__ import annotations

import json
import re
import shutil
import socket
import subprocess
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
import yaml
from deploy_helpers import (
    HEARD,
    compose_command,
    copy_project,
    free_udp_port,
    log_lines,
    project_containers,
    remove_project_containers,
    wait_for,
)

if TYPE_CHECKING:
    from conftest import RobocoreCli

pytestmark = pytest.mark.docker

HEAR_WITHIN = 60.0


def ids(client: Any, project: str) -> dict[str, str]:
    return {c.labels["dev.robocore.component"]: c.id for c in project_containers(client, project)}


@pytest.fixture
def project_copy(project_copies: Callable[..., Path]) -> Callable[..., Path]:
    """``project_copy(**copy_project options)``: a ``robocore-it-run-*`` copy of the demo project (conftest's
    ``project_copies``: its containers are removed when the test ends)."""
    return lambda **kwargs: project_copies("run", **kwargs)


@pytest.fixture
def compose_project() -> Iterator[Callable[[str, Path], list[str]]]:
    """``compose_project(name, file)``: the docker-compose command line of project ``name`` with that file;
    ``down -v`` of each when the test ends."""
    made: list[list[str]] = []

    def make(name: str, path: Path) -> list[str]:
        made.append([*compose_command(), "-p", name, "-f", str(path)])
        return made[-1]

    yield make
    for compose in made:
        subprocess.run([*compose, "down", "-v"], capture_output=True, timeout=300)


@pytest.fixture(scope="module")
def running(demo_project: Path, tmp_path_factory: pytest.TempPathFactory, docker_client: Any,
            run_robocore: RobocoreCli) -> Iterator[Path]:
    """One copy deployed with `robocore run` for the read-only tests (status, logs, connect)."""
    name = f"robocore-it-obs-{int(time.time()) % 100000}"
    root = copy_project(demo_project, tmp_path_factory.mktemp("running"), name)
    run_robocore(root, "run", "--quiet")
    listener = docker_client.containers.get(f"{root.name}-listener")
    assert wait_for(lambda: log_lines(listener, HEARD), HEAR_WITHIN), "listener heard nothing after run"
    yield root
    remove_project_containers(docker_client, root.name)


def test_run_is_idempotent_and_recreates_only_what_changed(project_copy: Any, docker_client: Any,
                                                          run_robocore: RobocoreCli) -> None:
    root = project_copy()
    run_robocore(root, "run")
    first = ids(docker_client, root.name)
    assert set(first) == {"discovery-0", "talker", "listener"}
    listener = docker_client.containers.get(f"{root.name}-listener")
    assert wait_for(lambda: log_lines(listener, HEARD), HEAR_WITHIN), "listener heard nothing"

    out = run_robocore(root, "run", "--json")
    assert ids(docker_client, root.name) == first, "a second run with nothing changed recreated containers"
    actions = json.loads(out.stdout)
    host = next(iter(actions["results"]))
    assert {a["verb"] for a in host["actions"]} == {"keep"}

    data = yaml.safe_load((root / "robot.yaml").read_text())
    listener_entry = next(c for c in data["components"] if c["name"] == "listener")
    listener_entry["environment"] = {"ROBOCORE_IT_CHANGED": "1"}
    # no priority: critical here: its --oom-score-adj -900 needs a daemon with CAP_SYS_RESOURCE, which the CI
    # machines' Docker lacks (runc: "can't get final child's PID from pipe"); its mapping is unit-tested
    listener_entry["resources"] = {"requests": {"cpu": 0.25, "memory": "64Mi"},
                                   "limits": {"cpu": "500m", "memory": "256Mi"}}
    (root / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    plan = run_robocore(root, "run", "--dry-run").stdout
    # offline: the plan names the containers, and what each host runs now is unknown (the run below decides)
    assert f"{root.name}-listener" in plan and f"{root.name}-talker" in plan
    assert "unknown (dry run: not contacted)" in plan
    assert ids(docker_client, root.name) == first, "--dry-run changed something"

    run_robocore(root, "run")
    second = ids(docker_client, root.name)
    changed = {name for name in first if first[name] != second[name]}
    assert changed == {"listener"}
    new_listener = docker_client.containers.get(f"{root.name}-listener")
    assert new_listener.attrs["Config"]["Env"].count("ROBOCORE_IT_CHANGED=1") == 1
    # robot.yaml's resources, as Docker runs the container (and it still hears, under those limits)
    host_config = new_listener.attrs["HostConfig"]
    assert (host_config["NanoCpus"], host_config["CpuShares"]) == (500_000_000, 256)
    assert (host_config["Memory"], host_config["MemoryReservation"]) == (256 << 20, 64 << 20)
    talker_config = docker_client.containers.get(f"{root.name}-talker").attrs["HostConfig"]
    assert (talker_config["NanoCpus"], talker_config["Memory"], talker_config["OomScoreAdj"]) == (0, 0, 0)
    assert wait_for(lambda: log_lines(new_listener, HEARD), HEAR_WITHIN), "recreated listener heard nothing"

    # A component removed from robot.yaml is removed from its host; the others stay.
    data["components"] = [c for c in data["components"] if c["name"] != "listener"]
    (root / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    run_robocore(root, "run")
    third = ids(docker_client, root.name)
    assert set(third) == {"discovery-0", "talker"} and third["talker"] == first["talker"]

    run_robocore(root, "down")
    assert ids(docker_client, root.name) == {}


def test_generated_compose_file_is_accepted_and_matches_run(project_copy: Any, docker_client: Any,
                                                           run_robocore: RobocoreCli) -> None:
    root = project_copy()
    run_robocore(root, "run", "--quiet")
    files = list((root / ".robocore" / "compose").glob("*.yaml"))
    assert files
    for path in files:
        proc = subprocess.run([*compose_command(), "-f", str(path), "config"], capture_output=True, text=True)
        assert proc.returncode == 0, proc.stderr
        services = yaml.safe_load(proc.stdout)["services"]
        for container in project_containers(docker_client, root.name, all=False):
            service = services[container.labels["dev.robocore.component"]]
            assert service["labels"]["dev.robocore.spec"] == container.labels["dev.robocore.spec"]
            assert service["network_mode"] == container.attrs["HostConfig"]["NetworkMode"] == "host"
            assert service["ipc"] == container.attrs["HostConfig"]["IpcMode"] == "host"


def test_missing_install_tree_says_build_first(project_copy: Any, docker_client: Any,
                                               run_robocore: RobocoreCli) -> None:
    root = project_copy()
    shutil.rmtree(root / ".robocore" / "build" / "listener")
    proc = run_robocore(root, "run", check=False)
    assert proc.returncode != 0
    assert "listener" in proc.stderr and "run build first" in proc.stderr
    assert ids(docker_client, root.name) == {}, "containers were started although the plan was refused"


def _lan_address() -> str:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.connect(("192.0.2.1", 9))  # no packet is sent; this only picks the outgoing interface
        return str(sock.getsockname()[0])


def test_unreachable_host_is_named_and_the_others_are_deployed(project_copy: Any, docker_client: Any,
                                                               run_robocore: RobocoreCli) -> None:
    def add_ghost(data: dict[str, Any]) -> None:
        first = data["hosts"][0]
        first["ip"] = _lan_address()  # a LAN address, so that a remote host could reach the server
        first["docker"] = "local"
        data["hosts"].append({"name": "ghost", "ip": "192.0.2.1", "user": "robot"})  # TEST-NET-1: never answers
        data["components"].append({"name": "phantom", "runs_on": "ghost", "image": "busybox:latest"})

    root = project_copy(edit=add_ghost)
    started = time.monotonic()
    proc = run_robocore(root, "run", check=False, timeout=120)
    elapsed = time.monotonic() - started
    assert proc.returncode == 8, proc.stderr  # GroupError
    assert "ghost" in proc.stderr and "192.0.2.1" in proc.stderr
    print(f"\nBENCH run with one unreachable host: {elapsed:.1f} s (goal: host named within 10 s)")
    assert elapsed < 20, f"run took {elapsed:.1f} s to give up on an unreachable host"
    assert set(ids(docker_client, root.name)) == {"discovery-0", "talker", "listener"}
    assert "failed" in proc.stdout and "ok" in proc.stdout  # the per-host summary


def test_an_empty_never_deployed_host_is_not_contacted(project_copy: Any, docker_client: Any,
                                                        run_robocore: RobocoreCli) -> None:
    """A spare machine listed in robot.yaml with nothing on it, and offline, must not fail the run;
    asked for by name (--host), it is contacted and named as unreachable (the control)."""
    def add_spare(data: dict[str, Any]) -> None:
        data["hosts"].append({"name": "spare", "ip": "192.0.2.1", "user": "robot"})  # TEST-NET-1: never answers

    root = project_copy(edit=add_spare)
    proc = run_robocore(root, "run", check=False, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "not contacted" in proc.stdout
    assert set(ids(docker_client, root.name)) == {"discovery-0", "talker", "listener"}
    named = run_robocore(root, "run", "--host", "spare", check=False, timeout=120)
    assert named.returncode == 8 and "spare" in named.stderr and "192.0.2.1" in named.stderr, named.stderr


def test_status_shows_components_and_nodes(running: Path, run_robocore: RobocoreCli) -> None:
    status = json.loads(run_robocore(running, "status", "--json", "--nodes").stdout)
    rows = {row["component"]: row for row in status["results"] if row["kind"] == "container"}
    assert set(rows) == {"discovery-0", "talker", "listener"}
    assert {row["state"] for row in rows.values()} == {"running"}
    assert rows["talker"]["image"].endswith("-talker:latest")
    [graph] = [r for r in status["results"] if r["kind"] == "ros_graph"]
    assert "/talker" in graph["nodes"] and "/listener" in graph["nodes"]
    table = run_robocore(running, "status", "--nodes").stdout
    assert "running" in table and "/listener" in table
    # without --nodes: the same containers (read over the daemon's socket), the graph not asked
    quick = json.loads(run_robocore(running, "status", "--json").stdout)
    def containers(data: dict[str, Any]) -> list[dict[str, Any]]:
        return [{k: v for k, v in r.items() if k != "uptime"} for r in data["results"] if r["kind"] == "container"]

    assert containers(quick) == containers(status)
    [graph] = [r for r in quick["results"] if r["kind"] == "ros_graph"]
    assert graph["nodes"] is None and "--nodes" in graph["via"]
    assert "--nodes" in run_robocore(running, "status").stdout


def table_rows(stdout: str) -> list[tuple[str, ...]]:
    """The status table's rows, without the uptime column (it changes between two runs)."""
    rows = [tuple(cell.strip() for cell in line.strip("│").split("│")) for line in stdout.splitlines()
            if line.startswith("│")]
    return [row[:3] + row[4:] for row in rows]


def test_plain_status_of_an_unchanged_project_answers_from_its_memo(running: Path,
                                                                   run_robocore: RobocoreCli) -> None:
    """The second plain status prints the ordinary table from the plan the first recorded (without loading
    robot.yaml's model); a plan edited in the memo shows that it is read, and a touched robot.yaml (same
    content) takes the ordinary path again (negative control)."""
    from robocore.commands.support import noop

    ordinary = run_robocore(running, "status", env={"ROBOCORE_NO_MEMO": "1"}).stdout
    run_robocore(running, "status")  # records the plan (or answers from a plan an earlier test recorded)
    [memo] = (running / ".robocore" / "noop").glob("status-*.json")
    fast = run_robocore(running, "status").stdout
    assert table_rows(fast) == table_rows(ordinary) and len(table_rows(fast)) == 3
    assert {row[2] for row in table_rows(fast)} == {"running"}
    assert fast.splitlines()[-1] == ordinary.splitlines()[-1]
    document = noop.unseal(memo.read_bytes())
    assert document is not None
    document["hosts"][0][1].append("ghost")  # type: ignore[index,union-attr]
    memo.write_text(noop.seal(document))  # resealed: an edit that breaks the checksum is dropped
    assert ("ghost", "devmachine", "missing", "0", "-") in table_rows(run_robocore(running, "status").stdout)
    (running / "robot.yaml").touch()
    assert not any(row[0] == "ghost" for row in table_rows(run_robocore(running, "status").stdout))


def test_logs_prefix_and_filter(running: Path, run_robocore: RobocoreCli) -> None:
    lines = run_robocore(running, "logs", "--tail", "5").stdout.splitlines()
    prefixes = {line.split("|", 1)[0].strip() for line in lines if "|" in line}
    assert {"talker", "listener"} <= prefixes
    assert any(line.startswith("listener") and HEARD in line for line in lines)
    only = run_robocore(running, "logs", "--component", "talker", "--tail", "5").stdout.splitlines()
    assert only and all(line.startswith("talker ") for line in only)


def test_logs_follow_merges_live_streams(running: Path, run_robocore: RobocoreCli) -> None:
    proc = run_robocore.start(running, "logs", "-f", "--tail", "0")
    seen: set[str] = set()
    deadline = time.monotonic() + 30
    assert proc.stdout is not None
    while time.monotonic() < deadline and not {"talker", "listener"} <= seen:
        line = proc.stdout.readline()
        if "|" in line:
            seen.add(line.split("|", 1)[0].strip())
    assert {"talker", "listener"} <= seen, f"followed streams: {seen}"


def test_connect_runs_commands_as_super_client(running: Path, run_robocore: RobocoreCli) -> None:
    proc = run_robocore(running, "connect", "--component", "listener", "--cmd", "exit 7", check=False)
    assert proc.returncode == 7
    out = run_robocore(running, "connect", "--component", "talker", "--cmd",
                       "echo super=$ROS_SUPER_CLIENT; ros2 node list --spin-time 3").stdout
    assert "super=TRUE" in out
    assert "/listener" in out and "/talker" in out
    missing = run_robocore(running, "connect", "--component", "nope", "--cmd", "true", check=False)
    assert missing.returncode == 2 and "unknown component" in missing.stderr


def test_connect_opens_an_interactive_shell_in_a_tty(running: Path, run_robocore: RobocoreCli) -> None:
    """`connect` without --cmd: docker exec -it in the live container, ROS sourced, super client."""
    proc = run_robocore.in_terminal(running, "connect", "--component", "listener",
                                    typed="echo tty=$(tty) super=$ROS_SUPER_CLIENT prefix=$AMENT_PREFIX_PATH; exit 5\n")
    text = proc.stdout
    assert proc.returncode == 5, text
    assert "tty=/dev/pts/" in text and "super=TRUE" in text, text
    # Sourcing the component's install tree puts it on AMENT_PREFIX_PATH (the echoed command itself has no match).
    assert re.search(r"prefix=\S*/robocore/install", text), f"the install tree is not sourced:\n{text}"


def _stop(container: Any, timeout: int) -> tuple[float, int]:
    """``docker stop -t timeout``: (seconds it took, the container's exit code)."""
    started = time.monotonic()
    container.stop(timeout=timeout)
    seconds = time.monotonic() - started
    container.reload()
    return seconds, int(container.attrs["State"]["ExitCode"])


@pytest.mark.quiet
def test_discovery_server_stops_gracefully_at_once(running: Path, docker_client: Any) -> None:
    """`docker stop` of the discovery server ends in well under Docker's 10 s: the container's init passes SIGTERM on
    and the server stops by itself (exit 0, not SIGKILL's 137). Started again, it serves the robot (a clean stop
    leaves no restart hold): a listener restarted after it hears the talker again. Control: the same server without
    the init ignores SIGTERM (PID 1 without a handler) and is killed when the stop's timeout ends."""
    from robocore.plan.containers import discovery_spec
    from robocore.project import Project

    server = docker_client.containers.get(f"{running.name}-discovery-0")
    listener = docker_client.containers.get(f"{running.name}-listener")
    assert server.attrs["HostConfig"]["Init"] is True
    seconds, code = _stop(server, 10)
    print(f"\nBENCH docker stop of a discovery server: {seconds:.2f} s, exit code {code}")
    assert seconds < 3 and code == 0, f"stopped in {seconds:.1f} s with exit code {code} (137: SIGKILL)"
    assert "Server shut down" in server.logs(tail=5).decode(errors="replace")
    server.start()
    listener.restart(timeout=2)  # a new participant: it can only find the talker through the restarted server
    before = len(log_lines(listener, HEARD))
    assert wait_for(lambda: len(log_lines(listener, HEARD)) > before, HEAR_WITHIN, interval=0.5), \
        "a listener restarted after the server's restart heard nothing"

    kwargs = discovery_spec(Project.load(running), 0).docker_kwargs()
    port = str(yaml.safe_load((running / "robot.yaml").read_text())["discovery"]["servers"][0]["port"])
    free = str(free_udp_port())
    kwargs.update(name=f"{running.name}-discovery-noinit", init=False, mounts=[],
                  command=[free if arg == port else arg for arg in kwargs["command"]])
    assert free in kwargs["command"]
    control = docker_client.containers.create(**kwargs)
    try:
        control.start()
        assert wait_for(lambda: b"Server is running" in control.logs(), 30), control.logs().decode(errors="replace")
        seconds, code = _stop(control, 3)
    finally:
        control.remove(force=True)
    assert seconds >= 2.5 and code == 137, f"without the init: stopped in {seconds:.1f} s with exit code {code}"


def test_compose_up_runs_the_robot_and_run_keeps_it(project_copy: Any, docker_client: Any, run_robocore: RobocoreCli,
                                                    compose_project: Callable[[str, Path], list[str]]) -> None:
    """The generated compose file is a working artifact: `docker-compose up` starts the robot, and robocore
    then sees exactly its own specs (same spec labels, same images) and recreates nothing."""
    from robocore.commands.support.composefiles import write_compose_files
    from robocore.project import Project

    root = project_copy()
    project = Project.load(root)
    (path,) = write_compose_files(project)
    compose = compose_project(root.name, path)
    up = subprocess.run([*compose, "up", "-d"], capture_output=True, text=True, timeout=300)
    assert up.returncode == 0, up.stderr
    listener = docker_client.containers.get(f"{root.name}-listener")
    assert wait_for(lambda: log_lines(listener, HEARD), HEAR_WITHIN), "compose-started listener heard nothing"
    started = ids(docker_client, root.name)
    assert set(started) == {"discovery-0", "talker", "listener"}
    out = json.loads(run_robocore(root, "run", "--json").stdout)
    assert {a["verb"] for host in out["results"] for a in host["actions"]} == {"keep"}
    assert ids(docker_client, root.name) == started


def test_golden_compose_files_are_accepted_by_docker_compose() -> None:
    """The unit tests' golden compose files (GPUs, devices, named volumes, ports, `$` escapes) pass `config`."""
    goldens = sorted((Path(__file__).parents[1] / "tests" / "golden" / "compose").glob("*.yaml"))
    assert goldens
    for path in goldens:
        proc = subprocess.run([*compose_command(), "-f", str(path), "config", "-q"], capture_output=True, text=True)
        assert proc.returncode == 0, f"{path.name}: {proc.stderr}"
        assert "variable is not set" not in proc.stderr, f"{path.name}: unescaped $: {proc.stderr}"


def test_discovery_port_taken_is_reported(project_copy: Any, docker_client: Any, run_robocore: RobocoreCli,
                                          tracked_containers: list[Any]) -> None:
    """Another server on the same UDP port (another project): run says so instead of reporting success."""
    root = project_copy()
    data = yaml.safe_load((root / "robot.yaml").read_text())
    port = data["discovery"]["servers"][0]["port"]
    image = f"{data['image_prefix']}base:latest"
    squatter = docker_client.containers.run(image, ["fastdds", "discovery", "-i", "0", "-p", str(port)],
                                            name=f"{root.name}-squatter", network_mode="host", detach=True)
    tracked_containers.append(squatter)
    assert wait_for(lambda: b"Server is running" in squatter.logs(), 30), squatter.logs().decode()
    proc = run_robocore(root, "run", check=False)
    assert proc.returncode == 8, proc.stderr
    assert "discovery-0 did not start" in proc.stderr and "UDP port" in proc.stderr


def test_edit_build_run_restarts_only_the_rebuilt_component(project_copy: Any, docker_client: Any,
                                                            run_robocore: RobocoreCli) -> None:
    """Local install trees are mounted in place: after `build`, `run` recreates the rebuilt component
    (whose process still runs the old code) and nothing else; the listener hears the new text."""
    root = project_copy()
    run_robocore(root, "run", "--quiet")
    first = ids(docker_client, root.name)
    code = root / "components" / "talker" / "src" / "demo_talker" / "demo_talker" / "talker.py"
    text = code.read_text()
    assert 'f"hello from talker #' in text
    code.write_text(text.replace('f"hello from talker #', 'f"rebuilt talker #'))
    run_robocore(root, "build", "--component", "talker", "--quiet")
    run_robocore(root, "run", "--quiet")
    second = ids(docker_client, root.name)
    assert {name for name in first if first[name] != second[name]} == {"talker"}
    listener = docker_client.containers.get(f"{root.name}-listener")
    assert wait_for(lambda: log_lines(listener, "rebuilt talker #"), HEAR_WITHIN), "the new code was never heard"
    again = json.loads(run_robocore(root, "run", "--json").stdout)
    assert {a["verb"] for host in again["results"] for a in host["actions"]} == {"keep"}
