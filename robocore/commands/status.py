"""status, logs and connect: looking at (and into) the running robot."""

from __future__ import annotations

import os
import queue
import shlex
import subprocess
import sys
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

from robocore.commands.support import status_memo
from robocore.commands.support.context import Options
from robocore.commands.support.hosts import connect as connect_host
from robocore.commands.support.hosts import (
    for_each_host,
    local_documents,
    managed_containers,
    managed_documents,
    select_hosts,
)
from robocore.commands.support.reporting import Reporter
from robocore.commands.support.status_table import (
    GRAPH_SPIN_SECONDS,
    NOT_ASKED,
    Row,
    host_rows,
    not_registered,
    print_status,
    stale_line,
)
from robocore.config.model import DockerAccess, Host
from robocore.errors import DockerError, GroupError, RobocoreError, UsageError
from robocore.plan import discovery, naming
from robocore.plan.addresses import url_host
from robocore.plan.containers import discovery_service
from robocore.project import Project
from robocore.ui import clean

if TYPE_CHECKING:
    import docker

#: Read timeout of log streams: a quiet component may print nothing for a long time.
LOG_STREAM_TIMEOUT = 7 * 24 * 3600


# --------------------------------------------------------------------------- status


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
            container = _running(client, naming.discovery_container_name(project.name, server.index))
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


def _running(client: docker.DockerClient, name: str) -> Any:
    from docker.errors import NotFound

    try:
        container = client.containers.get(name)
    except NotFound:
        return None
    return container if container.status == "running" else None


@dataclass(frozen=True)
class RosGraph:
    """The ROS nodes alive in the graph, and where they were asked (``nodes`` None when no server answered)."""

    kind: ClassVar[str] = "ros_graph"
    nodes: list[str] | None
    via: str
    #: Running components the ROS master does not know: they started before its last start.
    not_registered: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class LogLine:
    """One line a component's container logged."""

    kind: ClassVar[str] = "log"
    component: str
    host: str
    line: str


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


# --------------------------------------------------------------------------- logs


def _component_containers(project: Project, host: Host, component: str | None) -> list[tuple[str, Any]]:
    client = connect_host(project, host, timeout=LOG_STREAM_TIMEOUT)
    found = []
    for container in managed_containers(client, project.name):
        name = container.labels.get(naming.LABEL_COMPONENT, container.name)
        if component is None or name == component:
            found.append((name, container))
    return found


def logs(options: Options, *, component: str | None, follow: bool, tail: int) -> None:
    """Print container logs of all hosts, each line prefixed by its component; ``follow`` merges live streams.
    With JSON, each line is a result (and with ``follow`` one JSON object per line as it comes)."""
    project = options.load()
    report = options.report
    if component is not None and component not in {c.name for c in project.robot.components}:
        project.component(component)  # UsageError listing the known components
    hosts = [project.host(project.component(component).runs_on)] if component else select_hosts(project, None)
    if options.dry_run:
        for h in hosts:
            report.out(f"would read logs of {component or 'every container'} on {h.name}")
        return
    results, failures = for_each_host(hosts, lambda h: _component_containers(project, h, component))
    containers = [(h.name, *item) for h in hosts for item in sorted(results.get(h.name, []), key=lambda i: i[0])]
    for host, error in sorted(failures.items()):
        report.notice(f"{host}: {error.lines()[0]}", style="red")
    if not containers and not failures:
        report.notice(f"no {project.name} containers" + (f" for {component}" if component else "") + "; run `run`")
    width = max((len(name) for _, name, _ in containers), default=0)
    if not follow:
        for host, name, container in containers:
            for line in _lines(container.logs(tail=tail, stream=False)):
                _emit(report, LogLine(name, host, line), width, stream=False)
    else:
        _follow(report, containers, width, tail)
    if failures:
        raise GroupError(failures, list(results))


def _lines(data: bytes | Iterator[bytes]) -> Iterator[str]:
    chunks = [data] if isinstance(data, bytes) else data
    pending = b""
    for chunk in chunks:
        pending += chunk
        *complete, pending = pending.split(b"\n")
        for raw in complete:
            yield raw.decode(errors="replace").rstrip("\r")
    if pending:
        yield pending.decode(errors="replace")


def _emit(report: Reporter, log: LogLine, width: int, *, stream: bool) -> None:
    """One log line behind its component's name, or (JSON) a result, streamed at once when following.

    The line is the container's own output: its colours (SGR sequences, which ROS logging uses) are
    kept, any other control sequence (titles, cursor moves, screen clears) is escaped, and so is the
    name (a label read from the host)."""
    if report.json:
        if stream:
            report.stream(log)
        else:
            report.add(log)
        return
    sys.stdout.write(f"{clean(log.component):<{width}} | {clean(log.line, keep_sgr=True)}\n")
    sys.stdout.flush()


def _follow(report: Reporter, containers: list[tuple[str, str, Any]], width: int, tail: int) -> None:
    report.streamed = True  # with JSON: JSON Lines, the envelope last
    lines: queue.Queue[LogLine | None] = queue.Queue()

    def pump(host: str, name: str, container: Any) -> None:
        try:
            for line in _lines(container.logs(stream=True, follow=True, tail=tail)):
                lines.put(LogLine(name, host, line))
        except Exception as exc:  # a host going away ends its streams, not the others
            lines.put(LogLine(name, host, f"[log stream ended: {exc}]"))
        finally:
            lines.put(None)

    for host, name, container in containers:
        threading.Thread(target=pump, args=(host, name, container), daemon=True, name=f"logs-{name}").start()
    open_streams = len(containers)
    while open_streams:
        item = lines.get()
        if item is None:
            open_streams -= 1
        else:
            _emit(report, item, width, stream=True)


# --------------------------------------------------------------------------- connect


#: Interactive shell: bash when the image has it, else sh (a fixed script, nothing interpolated).
_SHELL = ["sh", "-c", "if command -v bash >/dev/null 2>&1; then exec bash; else exec sh; fi"]


def exec_argv(entrypoint: list[str] | None, command: list[str]) -> list[str]:
    """``command`` behind the container's own entrypoint (ours sources ROS and the install tree)."""
    return [*(entrypoint or []), *command]


def connect(options: Options, *, component: str, cmd: str | None) -> int:
    """A shell (or ``cmd``) in the live container of ``component`` on its host, as a ROS super client."""
    project = options.load()
    comp = project.component(component)
    host = project.host(comp.runs_on)
    name = naming.container_name(project.name, comp.name)
    env = discovery.for_robot(project.robot).observer_environment(host.name)
    command = _SHELL if cmd is None else ["sh", "-c", cmd]
    if options.dry_run:
        entry = None if comp.image else [naming.ENTRYPOINT]
        where = f"on {host.name} ({'interactive' if cmd is None else 'no tty'}), in {name}"
        options.report.plain(f"{where}: {shlex.join(exec_argv(entry, command))}")
        options.report.plain("environment: " + " ".join(f"{k}={v}" for k, v in sorted(env.items())))
        return 0
    client, container = _require_running(project, host, name, comp.name)
    entrypoint = container.attrs.get("Config", {}).get("Entrypoint") or None
    argv = exec_argv(entrypoint, command)
    if cmd is not None:
        return _exec_streaming(client, container, host, name, argv, env)
    client.close()
    tty = sys.stdin.isatty()
    full, extra_env = interactive_argv(project, host, docker_exec_argv(name, argv, env, tty=tty), tty=tty)
    if host.access is DockerAccess.ssh:
        from robocore.adapters import ssh

        ssh.require_ssh()
        ssh.ensure_control_dir()
    return subprocess.call(full, env={**os.environ, **extra_env})


def docker_exec_argv(name: str, argv: list[str], env: dict[str, str], *, tty: bool) -> list[str]:
    """``docker exec`` of ``argv`` in container ``name``: each variable attached to its flag
    (``--env=K=V``), ``--`` before the container name and the command."""
    return ["docker", "exec", "-it" if tty else "-i", *(f"--env={key}={value}" for key, value in sorted(env.items())),
            "--", name, *argv]


def interactive_argv(project: Project, host: Host, docker_argv: list[str], *,
                     tty: bool) -> tuple[list[str], dict[str, str]]:
    """The local argv of an interactive ``docker exec -it`` on ``host`` and extra environment for it
    (over ssh: the docker argv quoted argument by argument, after ``--`` and the destination)."""
    access = host.access
    if access is DockerAccess.local:
        return docker_argv, {}
    if access is DockerAccess.ssh:
        from robocore.adapters import ssh

        return ["ssh", "-t" if tty else "-T", *ssh.ssh_options(host), "--", ssh.destination(host),
                shlex.join(docker_argv)], {}
    if access is DockerAccess.tls and host.tls is not None:
        from robocore.adapters.docker_hosts import tls_files

        files = tls_files(host, project.root)
        tls = ["--tlsverify", f"--tlscacert={files.ca_cert}", f"--tlscert={files.client_cert}",
               f"--tlskey={files.client_key}"]
        tcp = f"tcp://{url_host(host.ip, host.docker_port or 2376)}"
        return ["docker", *tls, *docker_argv[1:]], {"DOCKER_HOST": tcp}
    return docker_argv, {"DOCKER_HOST": f"tcp://{url_host(host.ip, host.docker_port or 2375)}"}


def _require_running(project: Project, host: Host, name: str, component: str) -> tuple[docker.DockerClient, Any]:
    client = connect_host(project, host, timeout=60)
    container = _running(client, name)
    if container is None:
        client.close()
        raise UsageError(f"component {component} is not running on host {host.name} (container {name})",
                         hint="start it with `robocore run`; `robocore status` shows every component")
    return client, container


def _exec_streaming(client: docker.DockerClient, container: Any, host: Host, name: str, argv: list[str],
                    env: dict[str, str]) -> int:
    """Run ``argv`` in the container without a TTY, stream its output, return its exit code."""
    try:
        api = client.api
        exec_id = api.exec_create(container.id, argv, environment=env, stdout=True, stderr=True, tty=False)["Id"]
        for out, err in api.exec_start(exec_id, stream=True, demux=True):
            if out:
                sys.stdout.buffer.write(out)
                sys.stdout.flush()
            if err:
                sys.stderr.buffer.write(err)
                sys.stderr.flush()
        code = api.exec_inspect(exec_id).get("ExitCode")
    except Exception as exc:
        if type(exc).__module__.split(".")[0] in {"docker", "requests", "urllib3"}:
            raise DockerError(f"host {host.name}: exec in {name} failed: {exc}") from None
        raise
    finally:
        client.close()
    return int(code) if code is not None else 1

