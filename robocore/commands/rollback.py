"""rollback: each host back to the version it ran before its last run.

Every successful ``run`` appends what a host now runs (image tag, synced release per
component) to the host's release history (:mod:`robocore.commands.support.state`). ``rollback`` takes
each host back to the entry before the last one: it switches each component's ``current``
symlink back to the release it ran then (still on the host: sync keeps the last
:data:`~robocore.plan.sync.KEEP_RELEASES` releases) and re-runs that host with the tag it ran
then. A rollback is itself recorded, so a second rollback returns to where the first one started.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from robocore.commands.run import deploy_host
from robocore.commands.support.context import Options
from robocore.commands.support.hosts import for_each_host, select_hosts
from robocore.commands.support.state import history, read_synced, record_run, with_synced_release, write_synced
from robocore.config.model import Host
from robocore.errors import GroupError, HostError, RobocoreError, UsageError
from robocore.plan.containers import host_specs
from robocore.plan.sync import KEEP_RELEASES
from robocore.project import Project

# $1 = component root, $2 = release id: point current at an existing release, atomically.
_SWITCH_SCRIPT = """\
set -eu
cd -- "$1"
[ -d "releases/$2" ] || { echo "release $2 is no longer on this host" >&2; exit 3; }
rm -f -- .current.tmp
ln -s -- "releases/$2" .current.tmp
mv -T -- .current.tmp current
"""


@dataclass(frozen=True)
class Rollback:
    """What a host went back to: the tag it runs and each component's release."""

    kind: ClassVar[str] = "rollback"
    host: str
    tag: str | None
    releases: dict[str, str]


def rollback(options: Options, *, host: str | None) -> None:
    """Return each host (or ``--host``) to the version it ran before its last run."""
    project = options.load()
    report = options.report
    hosts = select_hosts(project, host)
    targets: dict[str, dict[str, Any]] = {}
    for h in hosts:
        runs = history(project, h.name)
        if len(runs) >= 2:
            targets[h.name] = runs[-2]
        elif host:
            raise UsageError(f"host {h.name}: no earlier version recorded in {project.history_file(h.name)}",
                             hint="rollback needs two successful runs of this host")
    if not targets:
        raise UsageError("no host has an earlier version to return to", hint="rollback needs two successful runs")
    chosen = [h for h in hosts if h.name in targets]
    if options.dry_run:
        for h in chosen:
            t = targets[h.name]
            report.notice(f"{h.name}: would run tag {t.get('tag') or 'latest'} with releases "
                          f"{t.get('releases') or '(local build output)'}")
        return

    def work(h: Host) -> Any:
        target = targets[h.name]
        _restore_releases(project, h, target.get("releases", {}))
        tag = target.get("tag")
        specs = with_synced_release(project, h, host_specs(project, h.name, tag=tag))
        outcome = deploy_host(project, h, specs, dry_run=False, report=report)
        record_run(project, h, tag)
        return outcome

    results, failures = for_each_host(chosen, work)
    for name in sorted(results):
        t = targets[name]
        report.add(Rollback(host=name, tag=t.get("tag"), releases=dict(t.get("releases") or {})))
        report.notice(f"{name}: back to tag {t.get('tag') or 'latest'}"
                      + (f", releases {t['releases']}" if t.get("releases") else ""))
    if failures:
        raise GroupError(failures, list(results))


def _restore_releases(project: Project, host: Host, releases: dict[str, str]) -> None:
    """Point each component's ``current`` back at ``releases[component]`` and record it as synced."""
    if host.is_local or not releases:
        return
    from robocore.adapters import ssh
    from robocore.plan.layout import component_root
    from robocore.plan.sync import is_release_id

    state = read_synced(project, host.name)
    for component, release_id in sorted(releases.items()):
        if not is_release_id(release_id):
            raise HostError(f"host {host.name}: history names an invalid release {release_id!r} for {component}")
        root = str(component_root(host, component))
        try:
            ssh.run(host, ["sh", "-c", _SWITCH_SCRIPT, "sh", root, release_id], timeout=60)
        except RobocoreError as exc:
            raise HostError(f"host {host.name}: cannot return {component} to release {release_id}: {exc.message}",
                            hint=f"sync keeps the last {KEEP_RELEASES} releases; older ones are gone") from None
        state[component] = {"release": release_id, "digest": ""}
    write_synced(project, host.name, state)
