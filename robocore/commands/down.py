"""down: stop and remove the robot's containers on every host (or one), discovery servers last."""

from __future__ import annotations

import contextlib

from robocore.commands.run import HostOutcome
from robocore.commands.support.context import DRY_RUN_UNKNOWN, Options
from robocore.commands.support.hosts import connect, for_each_host, managed_containers, select_hosts
from robocore.commands.support.reporting import Reporter
from robocore.config.model import Host
from robocore.errors import GroupError
from robocore.plan import naming
from robocore.plan.actions import Action
from robocore.plan.containers import state_volumes
from robocore.plan.naming import ROLE_DISCOVERY
from robocore.project import Project


def stop_host(project: Project, host: Host, *, dry_run: bool, report: Reporter, forget_servers: bool) -> HostOutcome:
    """Remove this project's containers from one host: components first, discovery servers last.

    ``forget_servers`` also removes the discovery servers' state volumes, so that the next start is
    a first start (no restart hold): right when every host goes down, wrong when clients elsewhere
    keep running. ``dry_run`` contacts no host: which containers it runs is unknown.
    """
    from docker.errors import NotFound
    from rich.markup import escape

    outcome = HostOutcome(host.name)
    if dry_run:
        outcome.notes.append(f"would remove every container labelled {naming.LABEL_PROJECT}={project.name}; "
                             f"which ones: {DRY_RUN_UNKNOWN}")
        return outcome
    client = connect(project, host)
    try:
        containers = managed_containers(client, project.name)
        containers.sort(key=lambda c: (c.labels.get(naming.LABEL_ROLE) == ROLE_DISCOVERY, c.name))
        for container in containers:
            outcome.actions.append(Action("remove", container.name))
            container.remove(force=True)
            report.info(f"[bold]{host.name}[/]: removed {escape(container.name)}", markup=True)
        if forget_servers:
            for volume in state_volumes(project, host.name):
                with contextlib.suppress(NotFound):
                    client.volumes.get(volume).remove(force=True)
    finally:
        client.close()
    return outcome


def down(options: Options, *, host: str | None) -> None:
    """Stop and remove this project's containers on every host (or ``--host``)."""
    project = options.load()
    report = options.report
    hosts = select_hosts(project, host)
    forget = host is None  # every host goes down: the next start of each server is a first start

    def work(h: Host) -> HostOutcome:
        return stop_host(project, h, dry_run=options.dry_run, report=report, forget_servers=forget)

    results, failures = for_each_host(hosts, work)
    report.add(*results.values())
    for name, out in results.items():
        for note in out.notes:
            report.out(f"{name}: {note}")
        if not options.dry_run and not out.actions:
            report.info(f"[bold]{name}[/]: nothing to remove", markup=True)
    if failures:
        raise GroupError(failures, list(results))
