"""status: the state of every component on every host, and with ``--nodes`` the ROS nodes alive in the graph."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

from robocore.commands.support import status_memo
from robocore.commands.support.context import Options
from robocore.commands.support.hosts import connect as connect_host
from robocore.commands.support.hosts import (
    for_each_host,
    local_documents,
    managed_documents,
    running_container,
    select_hosts,
)
from robocore.commands.support.status_table import (
    GRAPH_SPIN_SECONDS,
    NOT_ASKED,
    Row,
    host_rows,
    not_registered,
    print_status,
    stale_line,
)
from robocore.config.model import Host
from robocore.errors import GroupError, RobocoreError
from robocore.plan import discovery, naming
from robocore.plan.containers import discovery_service
from robocore.project import Project


def _rows(project: Project, host: Host, documents: list[dict[str, Any]] | None = None) -> list[Row]:
    if documents is None:
        documents = managed_documents(project, host)
    return host_rows(host.name, planned_on(project, host), documents)


def planned_on(project: Project, host: Host) -> list[str]:
    """The names status lists for ``host`` whether they run or not: its discovery servers, then its components."""
    planned = [discovery_service(s.index) for s in discovery.for_robot(project.robot).servers_on(host.name)]
    return planned + [c.name for c in project.robot.components_on(host.name)]


def super_client_exec_env(project: Project, host: str | None = None) -> dict[str, str]:
    """Observer environment for a container without the discovery files mounted (a server container on ``host``)."""
    return discovery.for_robot(project.robot).observer_environment(host, files=discovery.no_files)


def ros_nodes(project: Project) -> tuple[list[str] | None, str]:
    """Names of the ROS nodes alive in the graph, and where they were asked (None when no server answered).

    Runs the discovery kind's node listing (``ros2 node list``) as an observer inside a running server container.
    """
    notes = []
    kind = discovery.for_robot(project.robot)
    for server in kind.servers():
        host = project.robot.host(server.host)
        where = f"{discovery_service(server.index)} on {host.name}"
        try:
            client = connect_host(project, host, timeout=60)
        except RobocoreError as error:
            notes.append(f"{where}: {error.lines()[0]}")
            continue
        try:
            container = running_container(client, naming.discovery_container_name(project.name, server.index))
            if container is None:
                notes.append(f"{where}: not running" + (f"; {kind.server_down}" if kind.server_down else ""))
                continue
            argv = kind.node_list_argv(GRAPH_SPIN_SECONDS)
            code, output = container.exec_run(argv, environment=super_client_exec_env(project, host.name), demux=False)
        finally:
            client.close()
        text = (output or b"").decode(errors="replace")
        if code != 0:
            tool = " ".join(argv[1:3])
            notes.append(f"{where}: `{tool}` exited {code}: {text.strip().splitlines()[-1:] or ''}")
            continue
        return kind.nodes_from_output(text), where
    return None, "; ".join(notes) or "no discovery server"


@dataclass(frozen=True)
class RosGraph:
    """The ROS nodes alive in the graph, and where they were asked (``nodes`` None when no server answered)."""

    kind: ClassVar[str] = "ros_graph"
    nodes: list[str] | None
    via: str
    #: Running components the ROS master does not know: they started before its last start.
    not_registered: list[str] = field(default_factory=list)


def collect_status(project: Project, hosts: list[Host]) -> tuple[list[Row], dict[str, RobocoreError]]:
    """Status rows of every reachable host (file order) and the failures of the others. Local hosts are read
    over the daemon's socket first; the rest (or a local host whose socket did not answer) through docker-py,
    side by side."""
    local = {h.name: _rows(project, h, docs) for h in hosts if (docs := local_documents(project, h)) is not None}
    results, failures = for_each_host([h for h in hosts if h.name not in local], lambda h: _rows(project, h))
    results.update(local)
    rows = [row for h in hosts for row in results.get(h.name, [])]
    return rows, failures


def status(options: Options, *, nodes_too: bool = False) -> None:
    """Print the state of every component and, with ``nodes_too``, the ROS nodes alive in the graph (listening
    to the graph takes :data:`GRAPH_SPIN_SECONDS`; the containers alone answer at once)."""
    memo = status_memo.memo_for(options.argv)
    if memo is not None:
        memo.begin()  # the snapshot before robot.yaml is read: the plan is kept only if nothing changed since
    project = options.load()
    report = options.report
    hosts = select_hosts(project, None)
    if options.dry_run:
        for h in hosts:
            report.out(f"would list {project.name} containers on {h.name}")
        if nodes_too:
            report.out("would run `ros2 node list` as a super client in the discovery server container")
        return
    rows, failures = collect_status(project, hosts)
    nodes, where = ros_nodes(project) if nodes_too else (None, NOT_ASKED)
    kind = discovery.for_robot(project.robot)
    servers = [discovery_service(s.index) for s in kind.servers()]
    stale = not_registered(rows, servers) if kind.nodes_register_once else []
    report.add(*rows, RosGraph(nodes, where, stale))
    if not options.json:
        print_status(rows, failures, nodes, where, report=report)
        if stale:
            report.out(stale_line(stale))
    if failures:
        raise GroupError(failures, sorted({r.host for r in rows}))
    if memo is not None and memo.project.resolve() == project.root and all(h.is_local for h in hosts):
        status_memo.record(memo, status_memo.plan_document(
            project.name, [(h.name, planned_on(project, h)) for h in hosts], servers,
            register_once=kind.nodes_register_once))
