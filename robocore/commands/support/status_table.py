"""The status table: a row per container of the robot on each host, from Docker's inspect documents.

Pure and light (no configuration model, docker-py or invoke): the ordinary ``status`` builds its rows here
from robot.yaml's plan, and so does its fast path (:mod:`robocore.commands.support.status_memo`) from a recorded plan.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Any, ClassVar

from robocore.commands.support.reporting import Reporter
from robocore.errors import RobocoreError
from robocore.plan import naming
from robocore.plan.starts import docker_time, started_before_servers

#: Seconds ``status`` lets its super client listen to the graph.
GRAPH_SPIN_SECONDS = 3.0
#: Where the ROS nodes were asked when they were not (``status`` without ``--nodes``).
NOT_ASKED = f"not asked (`status --nodes` lists them, listening to the graph for {GRAPH_SPIN_SECONDS:.0f} s)"


@dataclass(frozen=True)
class Row:
    """One line of the status table: a container of the robot on its host."""

    kind: ClassVar[str] = "container"
    component: str
    host: str
    state: str
    uptime: str
    restarts: int
    image: str
    #: When the container last started (Docker's RFC 3339 ``State.StartedAt``), None when it is not running.
    started_at: str | None = None


def not_registered(rows: Sequence[Row], servers: Sequence[str]) -> list[str]:
    """The running components that started before the running discovery servers' last start (``servers``:
    their component names): a server whose nodes register only when they start does not know them."""
    stale = started_before_servers({r.component: r.started_at or "" for r in rows}, servers)
    return [r.component for r in rows if r.component in stale]


def uptime_text(started_at: str, now: datetime | None = None) -> str:
    """``3d 2h``, ``5m 10s``... from Docker's ``State.StartedAt`` (RFC 3339, nanoseconds)."""
    stamp = docker_time(started_at)  # whole seconds are enough
    stamp = stamp.replace(microsecond=0) if stamp is not None else None
    if stamp is None or stamp.year < 2000:
        return "-"
    seconds = int(((now or datetime.now(timezone.utc)) - stamp).total_seconds())
    days, rest = divmod(max(seconds, 0), 86400)
    hours, rest = divmod(rest, 3600)
    minutes, secs = divmod(rest, 60)
    if days:
        return f"{days}d {hours}h"
    if hours:
        return f"{hours}h {minutes}m"
    return f"{minutes}m {secs}s" if minutes else f"{secs}s"


def document_labels(document: dict[str, Any]) -> dict[str, str]:
    """The labels of a container's inspect document."""
    labels = (document.get("Config") or {}).get("Labels") or {}
    return {str(key): str(value) for key, value in labels.items()}


def managed(documents: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The documents of containers ``run`` manages (a component or a discovery server)."""
    return [doc for doc in documents if document_labels(doc).get(naming.LABEL_ROLE) in naming.MANAGED_ROLES]


def host_rows(host: str, planned: Sequence[str], documents: Sequence[dict[str, Any]]) -> list[Row]:
    """The rows of ``host``: each ``planned`` name in order (``missing`` when no container has it), then the
    project's other managed containers found there (``not planned``)."""
    found = {document_labels(doc).get(naming.LABEL_COMPONENT, str(doc.get("Name", "")).lstrip("/")): doc
             for doc in documents}
    rows = []
    for name in [*planned, *sorted(set(found) - set(planned))]:
        container = found.get(name)
        if container is None:
            rows.append(Row(name, host, "missing", "-", 0, "-"))
            continue
        state = container.get("State") or {}
        running = state.get("Status") == "running"
        rows.append(Row(
            component=name,
            host=host,
            state=str(state.get("Status", "unknown")) + ("" if name in planned else " (not planned)"),
            uptime=uptime_text(state.get("StartedAt", "")) if running else "-",
            restarts=int(container.get("RestartCount", 0)),
            image=str((container.get("Config") or {}).get("Image", "")),
            started_at=str(state.get("StartedAt", "")) if running else None,
        ))
    return rows


def stale_line(stale: Sequence[str]) -> str:
    """What status says of components a restarted ROS master does not know."""
    return (f"not registered with the ROS master, which started again after them: {', '.join(stale)} "
            "(`robocore run` restarts them)")


def print_status(rows: list[Row], failures: dict[str, RobocoreError], nodes: list[str] | None, where: str, *,
                 report: Reporter | None = None) -> None:
    """The status table, then the ROS nodes line."""
    from rich.markup import escape
    from rich.table import Table

    table = Table(title="robot status", title_justify="left")
    for column in ("component", "host", "state", "uptime", "restarts", "image"):
        table.add_column(column, no_wrap=column in {"component", "image"})
    colors = {"running": "green", "missing": "red"}
    for row in rows:  # what the hosts said is text, never rich markup
        color = colors.get(row.state.split()[0] if row.state.split() else "", "yellow")
        table.add_row(escape(row.component), row.host, f"[{color}]{escape(row.state)}[/]", escape(row.uptime),
                      str(row.restarts), escape(row.image))
    for host, error in sorted(failures.items()):
        table.add_row("-", host, "[red]unreachable[/]", "-", "-", escape(error.lines()[0]))
    report = report or Reporter()
    report.table(table)
    if nodes is None and where == NOT_ASKED:
        report.out(f"ROS nodes: {where}")
    elif nodes is None:
        report.out(f"ROS nodes: unknown ({where})")
    else:
        report.out(f"ROS nodes ({len(nodes)}, via {where}): " + (", ".join(nodes) if nodes else "none"))
