"""One host, real containers, real rclpy nodes: discovery through the generated Fast DDS configuration.

Every positive test has a negative control that would pass by accident if the path under test
were not the one carrying the messages:

- talker and listener from the generated config exchange messages through the discovery server, and
  the test process's probe (robocore's pytest plugin) sees both nodes and the talker's messages; the
  same containers and probe with no server running see and hear nothing;
- with the generated shared-memory settings (host network + ipc host) data flows between
  containers of one host; the same pair with private IPC namespaces discovers the topic and
  receives nothing; the generated UDP-only settings work with private IPC;
- the discovery server container is SIGKILLed and started again (a crash, a power cut: it says no
  goodbye) and a restarted listener finds the talker again (the seconds it takes are printed); without
  robocore's restart hold it never does (Fast DDS 2.x); a graceful restart (SIGTERM, under Docker's
  init the server unregisters itself before it ends) needs no hold;
- with two redundant servers, losing one still lets a restarted listener find the talker; with a
  single server lost, it finds nothing.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import lanes
import pytest
from deploy_helpers import HEARD, PUBLISHED, free_udp_port, log_lines, wait_for

from robocore.commands.support.composefiles import write_compose_files
from robocore.plan import naming
from robocore.plan.containers import ContainerSpec, host_specs
from robocore.project import Project

pytestmark = pytest.mark.docker

#: Seconds a negative control listens for messages that must not come.
SILENCE = 20.0
#: Seconds a positive test waits for messages.
HEAR_WITHIN = 60.0


class Deployment:
    """Containers of one project created straight from its generated specs (no `run`: controls edit specs)."""

    def __init__(self, client: Any, project: Project) -> None:
        self.client = client
        self.project = project
        self.containers: dict[str, Any] = {}
        write_compose_files(project)  # the DDS profiles the components mount
        self.host = project.robot.hosts[0].name

    def specs(self) -> dict[str, ContainerSpec]:
        return {s.service: s for s in host_specs(self.project, self.host)}

    def start(self, spec: ContainerSpec) -> Any:
        container = self.client.containers.create(**spec.docker_kwargs())
        container.start()
        self.containers[spec.service] = container
        return container

    def heard(self) -> list[str]:
        return log_lines(self.containers["listener"], HEARD)

    def graph(self, what: str = "node") -> str:
        """``ros2 <what> list`` as a super client inside the discovery server container."""
        from robocore.commands.status import super_client_exec_env

        code, out = self.containers["discovery-0"].exec_run(
            [naming.ENTRYPOINT, "ros2", what, "list", "--spin-time", "3"],
            environment=super_client_exec_env(self.project))
        assert code == 0, out.decode(errors="replace")
        return str(out.decode(errors="replace"))


@pytest.fixture
def deployment(project_copies: Callable[..., Path], docker_client: Any) -> Callable[..., Deployment]:
    """A factory of deployments of ``robocore-it-dds-*`` copies of the demo project (conftest's
    ``project_copies``: every container is removed when the test ends)."""

    def make(transport: str = "shm", servers: int = 1) -> Deployment:
        def more_servers(data: dict[str, Any]) -> None:
            host = data["hosts"][0]["name"]
            data["discovery"]["servers"] = [{"host": host, "port": free_udp_port()} for _ in range(servers)]

        root = project_copies("dds", transport=transport, edit=more_servers if servers > 1 else None)
        return Deployment(docker_client, Project.load(root))

    return make


def test_without_a_discovery_server_nothing_is_heard(robot_run: Any) -> None:
    """Negative control: the same generated talker, listener and probe, no server running. It runs first, so that
    the next test's probe is the second of this process: it must use its own robot's servers (Fast DDS reads a
    process's profile file once, so the probe's file names none)."""
    robot = robot_run(servers=False)
    robot.wait_for_log("talker", PUBLISHED, timeout=HEAR_WITHIN)
    robot.graph.spin(SILENCE)
    assert "Publishing" in robot.logs("talker").splitlines()[-1], "talker stopped publishing"
    assert robot.graph.node_names() == set(), "the probe saw nodes without a discovery server"
    assert HEARD not in robot.logs("listener"), \
        "listener heard the talker without a discovery server: discovery is not via the server"


def test_messages_flow_through_the_discovery_server(robot_run: Any) -> None:
    """The plugin's probe (a super client in the test process, over UDP) sees the graph the server relays."""
    from std_msgs.msg import String

    robot = robot_run()
    robot.graph.wait_for_node("/talker", timeout=HEAR_WITHIN)
    robot.graph.wait_for_node("/listener", timeout=HEAR_WITHIN)
    msg = robot.graph.wait_for_message("/chatter", String, timeout=HEAR_WITHIN)
    assert msg.data.startswith("hello from talker #")
    robot.wait_for_log("listener", "I heard: hello from talker #", timeout=HEAR_WITHIN)


def test_same_host_private_ipc_discovers_but_receives_nothing(deployment: Any) -> None:
    """Negative control of the ipc handling: shared memory allowed, private IPC namespaces."""
    dep = deployment("shm")
    specs = dep.specs()
    assert specs["talker"].ipc_mode == "host" and specs["listener"].ipc_mode == "host"
    dep.start(specs["discovery-0"])
    dep.start(replace(specs["talker"], ipc_mode=None))
    dep.start(replace(specs["listener"], ipc_mode=None))
    assert wait_for(lambda: log_lines(dep.containers["talker"], PUBLISHED), HEAR_WITHIN), "the talker never published"
    # Discovery works: the server knows the talker's and the listener's /chatter endpoints...
    assert wait_for(lambda: "/chatter" in dep.graph("topic"), 30), "the topic was never discovered"
    time.sleep(SILENCE)
    # ...but Fast DDS picks shared memory between them, which private IPC namespaces cannot share.
    assert dep.heard() == [], "data arrived with private IPC: this control no longer proves the ipc setting"


def test_udp_transport_works_with_private_ipc(deployment: Any) -> None:
    dep = deployment("udp")
    specs = dep.specs()
    assert specs["listener"].ipc_mode is None
    assert specs["listener"].env["FASTDDS_BUILTIN_TRANSPORTS"] == "UDPv4"
    for spec in specs.values():
        dep.start(spec)
    assert wait_for(dep.heard, HEAR_WITHIN), "UDP-only listener heard nothing"


def _restart_server_and_listener(dep: Deployment, timeout: float, *, graceful: bool = False,
                                 down_for: float = 0.0) -> float | None:
    """Restart the server, then the listener (a new participant that can only find the talker through the
    restarted server); return the seconds until it hears the talker, None if it does not within ``timeout``.

    The server is SIGKILLed and started again ``down_for`` s later (it ends without a goodbye: what its restart
    hold is for), or with ``graceful`` restarted by Docker (SIGTERM: it unregisters itself from its clients
    before it ends)."""
    assert wait_for(dep.heard, HEAR_WITHIN), "no messages before the restart"
    server, listener = dep.containers["discovery-0"], dep.containers["listener"]
    started = time.monotonic()
    if graceful:
        server.restart(timeout=10)
        assert "shut down" in server.logs().decode(errors="replace"), "the server did not end cleanly on SIGTERM"
    else:
        server.kill()
        time.sleep(down_for)
        server.start()
    listener.restart(timeout=2)
    # The old listener process is gone: every "I heard" line from now on is the new one's.
    before = len(dep.heard())
    resumed = wait_for(lambda: len(dep.heard()) > before, timeout, interval=0.25)
    return time.monotonic() - started if resumed else None


@pytest.mark.quiet
def test_discovery_server_restart_recovers(deployment: Any) -> None:
    """The server container is SIGKILLed and started 4 s later; a listener started after it finds the talker
    again. The server holds only what is left of its hold since its last heartbeat (12 + 1 - 4 or 5 s, in whole
    seconds), not all of it. Prints the seconds."""
    dep = deployment()
    with lanes.untimed():  # the bring-up times nothing: the other lanes may work meanwhile
        for spec in dep.specs().values():
            dep.start(spec)
        assert wait_for(dep.heard, HEAR_WITHIN), "no messages before the restart"
    seconds = _restart_server_and_listener(dep, 90, down_for=4.0)
    shown = f"{seconds:.1f} s" if seconds is not None else "no recovery in 90 s"
    print(f"\nBENCH discovery-server killed, started 4 s later -> restarted listener hears the talker: {shown}")
    assert seconds is not None, "traffic did not resume within 90 s of a discovery server restart"
    held = re.findall(r"silent for (\d+) s", dep.containers["discovery-0"].logs().decode(errors="replace"))
    assert held and 6 <= int(held[-1]) <= 9, f"the hold after 4 s down was not what was left of 12 s: {held}"


def test_restart_without_the_hold_never_recovers(deployment: Any) -> None:
    """Negative control of the restart hold: a 2.x server that serves again at once (same GUID) leaves the
    talker with a stale proxy of it, and the restarted listener never matches the talker."""
    dep = deployment()
    specs = dep.specs()
    if dep.project.robot.fastdds_line >= 3:
        pytest.fail("this control is about Fast DDS 2.x (the demo project's distro changed)")
    env = {**specs["discovery-0"].env, "ROBOCORE_DS_HOLD": "0"}
    dep.start(replace(specs["discovery-0"], environment=tuple(sorted(env.items()))))
    dep.start(specs["talker"])
    dep.start(specs["listener"])
    assert _restart_server_and_listener(dep, 40) is None, \
        "recovered without the hold: the hold may no longer be needed (check dds.restart_hold_seconds)"


@pytest.mark.quiet
def test_a_graceful_restart_holds_nothing_and_needs_nothing(deployment: Any) -> None:
    """The control's counterpart: the server as ``run`` plans it (its 12 s hold set), restarted gracefully, says
    goodbye (it runs under Docker's init, which passes SIGTERM on), so its clients drop it; it ended cleanly, so
    it starts again without its hold, and a listener started after it hears the talker well within the hold."""
    dep = deployment()
    specs = dep.specs()
    assert specs["discovery-0"].env["ROBOCORE_DS_HOLD"] == "12"
    with lanes.untimed():  # the bring-up times nothing: the other lanes may work meanwhile
        for spec in specs.values():
            dep.start(spec)
        assert wait_for(dep.heard, HEAR_WITHIN), "no messages before the restart"
    seconds = _restart_server_and_listener(dep, 40, graceful=True)
    assert seconds is not None, "a graceful restart did not recover within 40 s"
    print(f"\nBENCH graceful discovery-server restart -> restarted listener hears the talker: {seconds:.1f} s")
    logged = dep.containers["discovery-0"].logs().decode(errors="replace")
    assert "silent for" not in logged, "the server held back after a clean stop"
    assert seconds < 8, f"heard again only after {seconds:.1f} s"


def lose_server_0_and_restart_listener(dep: Any) -> int:
    """Remove discovery server 0, restart the listener (it must discover again); return how much it had heard."""
    dep.containers["discovery-0"].remove(force=True)
    dep.containers["listener"].restart(timeout=2)
    return len(dep.heard())


def test_redundant_servers_survive_losing_one(deployment: Any) -> None:
    """Two servers: with server 0 gone, a restarted listener still finds the talker through server 1."""
    dep = deployment(servers=2)
    specs = dep.specs()
    assert list(specs) == ["discovery-0", "discovery-1", "talker", "listener"]
    for spec in specs.values():
        dep.start(spec)
    assert wait_for(dep.heard, HEAR_WITHIN), "no messages with two servers"
    before = lose_server_0_and_restart_listener(dep)
    assert wait_for(lambda: len(dep.heard()) > before, HEAR_WITHIN), \
        "the restarted listener did not find the talker through the remaining server"


def test_single_server_lost_means_no_new_discovery(deployment: Any) -> None:
    """Negative control of the redundancy test: one server, removed, and the restarted listener hears nothing."""
    dep = deployment()
    for spec in dep.specs().values():
        dep.start(spec)
    assert wait_for(dep.heard, HEAR_WITHIN), "no messages before removing the server"
    before = lose_server_0_and_restart_listener(dep)
    time.sleep(SILENCE)
    assert len(dep.heard()) == before, "a restarted listener found the talker with no server running"
