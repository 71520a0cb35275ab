"""logs: the robot's container logs on every host, each line behind its component (``--follow``: live)."""

from __future__ import annotations

import queue
import sys
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, ClassVar

from robocore.commands.support.context import Options
from robocore.commands.support.hosts import connect as connect_host
from robocore.commands.support.hosts import for_each_host, managed_containers, select_hosts
from robocore.commands.support.reporting import Reporter
from robocore.config.model import Host
from robocore.errors import GroupError
from robocore.plan import naming
from robocore.project import Project
from robocore.ui import clean

#: Read timeout of log streams: a quiet component may print nothing for a long time.
LOG_STREAM_TIMEOUT = 7 * 24 * 3600


@dataclass(frozen=True)
class LogLine:
    """One line a component's container logged."""

    kind: ClassVar[str] = "log"
    component: str
    host: str
    line: str


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
            for line in split_lines(container.logs(tail=tail, stream=False)):
                emit_line(report, LogLine(name, host, line), width, stream=False)
    else:
        follow_logs(report, containers, width, tail)
    if failures:
        raise GroupError(failures, list(results))


def split_lines(data: bytes | Iterator[bytes]) -> Iterator[str]:
    """The lines of a log, given whole or in chunks that need not end at a line's end."""
    chunks = [data] if isinstance(data, bytes) else data
    pending = b""
    for chunk in chunks:
        pending += chunk
        *complete, pending = pending.split(b"\n")
        for raw in complete:
            yield raw.decode(errors="replace").rstrip("\r")
    if pending:
        yield pending.decode(errors="replace")


def emit_line(report: Reporter, log: LogLine, width: int, *, stream: bool) -> None:
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


def follow_logs(report: Reporter, containers: list[tuple[str, str, Any]], width: int, tail: int) -> None:
    """Merge the live log streams of ``containers`` (host, name, container), each from its last ``tail`` lines,
    printing each line as it comes (:func:`emit_line`) until every stream ends or the user interrupts."""
    report.streamed = True  # with JSON: JSON Lines, the envelope last
    lines: queue.Queue[LogLine | None] = queue.Queue()

    def pump(host: str, name: str, container: Any) -> None:
        try:
            for line in split_lines(container.logs(stream=True, follow=True, tail=tail)):
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
            emit_line(report, item, width, stream=True)
