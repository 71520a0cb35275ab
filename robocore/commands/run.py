"""run: create, replace or remove each host's containers (``down`` removes them all: :mod:`robocore.commands.down`).

``run`` compares each planned :class:`~robocore.plan.containers.ContainerSpec` with what the
host runs: a container whose spec hash label and image ID match is left alone, a changed
one is recreated alone, a missing one is created, and robocore containers of this project
that are no longer planned on that host are removed. Hosts are handled in parallel; a host
that fails (unreachable, missing image, ...) does not stop the others, and the command ends
with a per-host summary and a :class:`~robocore.errors.GroupError`.
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

from robocore.commands.support.arch_checks import allowing_emulation, refuse_daemon_arch
from robocore.commands.support.composefiles import write_compose_files
from robocore.commands.support.context import DRY_RUN_UNKNOWN, Options
from robocore.commands.support.hosts import (
    connect,
    each_or_first_error,
    for_each_host,
    managed_containers,
    select_hosts,
    short_error,
)
from robocore.commands.support.reporting import Reporter
from robocore.commands.support.state import history, record_run, with_local_build, with_synced_release
from robocore.config.model import Host
from robocore.errors import DockerError, GroupError, RobocoreError, UsageError
from robocore.plan import discovery, naming
from robocore.plan.actions import Action, Existing, decide, in_stages, servers_started, with_node_restarts
from robocore.plan.containers import ContainerSpec, host_specs
from robocore.plan.naming import ROLE_DISCOVERY
from robocore.plan.release import is_released
from robocore.plan.starts import latest_start
from robocore.project import Project

if TYPE_CHECKING:
    import docker

#: Verb of a dry run's action: what the host runs now is not known.
UNKNOWN = "unknown"
#: Note of a host ``run`` leaves alone: nothing planned there, and no run of this project ever reached it.
NOT_CONTACTED = "nothing planned, never deployed here: not contacted"
#: Containers of one host created and started at once: the connections a Docker client over ssh keeps open.
SIDE_BY_SIDE = 4


@dataclass
class HostOutcome:
    """What happened on one host (``ok`` false and ``error`` its first line when the host failed)."""

    kind: ClassVar[str] = "host_run"
    host: str
    actions: list[Action] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    ok: bool = True
    error: str | None = None

    def count(self, verb: str) -> int:
        """How many actions have ``verb``."""
        return sum(1 for a in self.actions if a.verb == verb)


def _existing(container: Any) -> Existing:
    labels, attrs = container.labels, container.attrs
    return Existing(name=container.name, spec_hash=labels.get(naming.LABEL_SPEC), image_id=attrs.get("Image", ""),
                    running=container.status == "running", role=labels.get(naming.LABEL_ROLE, ""),
                    started_at=_started_at(container))


def _started_at(container: Any) -> str:
    """When ``container`` last started (Docker's RFC 3339 ``State.StartedAt``), "" when Docker does not say."""
    return str(container.attrs.get("State", {}).get("StartedAt", ""))


def check_install_trees(project: Project, host: Host) -> None:
    """Local hosts mount ``.robocore/build/<c>/install`` directly: it must exist."""
    if not host.is_local:
        return
    from robocore.plan.layout import host_paths

    for comp in project.robot.components_on(host.name):
        if comp.has_workspace and not Path(host_paths(project, host, comp.name).install).is_dir():
            raise UsageError(
                f"component {comp.name}: no install tree at {host_paths(project, host, comp.name).install}",
                hint=f"run build first (`robocore build --component {comp.name}`)",
            )


def _robocore_images(specs: Sequence[ContainerSpec], project: Project) -> list[str]:
    """robocore's images on this machine that ``specs`` run (not a release's, which hosts pull themselves)."""
    own = {c.image for c in project.robot.components if c.image}
    return sorted({s.image for s in specs if s.image not in own and not is_released(project.robot.registry, s.image)})


def _image_id(client: docker.DockerClient, ref: str) -> str | None:
    from docker.errors import ImageNotFound

    try:
        return str(client.images.get(ref).id)
    except ImageNotFound:
        return None


def host_image_ids(
    client: docker.DockerClient, local: docker.DockerClient | None, specs: Sequence[ContainerSpec], project: Project,
    host: Host, *, dry_run: bool, known: dict[str, str] | None = None,
) -> dict[str, str]:
    """Image reference -> ID the host must run; robocore images must exist (on this machine for remote hosts).
    ``known``: the IDs a delivery just read, which are not asked for again."""
    ids: dict[str, str] = dict(known or {})
    ours = set(_robocore_images(specs, project))
    for spec in specs:
        if spec.image in ids:
            continue
        source = local if (spec.image in ours and local is not None) else client
        image_id = _image_id(source, spec.image)
        if image_id is None and spec.image not in ours and not dry_run:
            try:
                client.images.pull(spec.image)
            except Exception as exc:
                raise DockerError(f"host {host.name}: image {spec.image} is missing and could not be pulled: "
                                  f"{short_error(exc)}") from None
            image_id = _image_id(client, spec.image)
        if image_id is None and spec.image in ours:
            step = "prepare-base" if spec.role == ROLE_DISCOVERY else "stage"
            raise DockerError(f"host {host.name}: image {spec.image} does not exist",
                              hint=f"run `robocore {step}` first")
        if image_id is not None:
            ids[spec.image] = image_id
    return ids


def deploy_host(project: Project, host: Host, specs: Sequence[ContainerSpec], *, dry_run: bool,
                report: Reporter, servers_restarted: bool = False,
                server_start: datetime | None = None) -> HostOutcome:
    """Bring one host to its planned containers (or, with ``dry_run``, say what that would take from what
    is known here: the host is not contacted, so what it runs now is unknown). ``servers_restarted``: a
    discovery server on another host was (re)started earlier in this run; ``server_start``: when the
    discovery server on another host last started."""
    outcome = HostOutcome(host.name)
    if dry_run:
        try:
            check_install_trees(project, host)
        except UsageError as error:
            outcome.notes.append(f"would fail: {error.message}")
        what = f"create, replace, start or keep: {DRY_RUN_UNKNOWN}"
        outcome.actions = [Action(UNKNOWN, spec.name, f"{spec.image}; {what}") for spec in specs]
        return outcome
    check_install_trees(project, host)
    specs = with_local_build(project, host, specs)
    client = connect(project, host)
    local = None
    known: dict[str, str] = {}
    try:
        emulated = refuse_daemon_arch(host, str(client.info().get("Architecture", "?"))).emulated
        if not host.is_local:
            from robocore.adapters.docker_hosts import local_client

            local = local_client(timeout=600)  # also streams images (docker save) to the host
            if not dry_run:
                known = _deliver(client, local, specs, project, host, outcome, report=report)
        image_ids = host_image_ids(client, local, specs, project, host, dry_run=dry_run, known=known)
        containers = {c.name: c for c in managed_containers(client, project.name)}
        _check_name_conflicts(client, specs, containers, host)
        kind = discovery.for_robot(project.robot)
        existing = [_existing(c) for c in containers.values()]
        actions = with_node_restarts(decide(specs, existing, image_ids), specs, register_once=kind.nodes_register_once,
                                     elsewhere=servers_restarted, existing=existing, server_start=server_start)
        outcome.actions = actions
        if dry_run:
            return outcome
        by_name = {s.name: s for s in specs}
        timeout = allowing_emulation(SERVER_READY_TIMEOUT, emulated=emulated)
        for stage in in_stages(actions, {s.name for s in specs if s.role == ROLE_DISCOVERY}):
            each_or_first_error(stage, lambda a: apply_action(client, a, by_name.get(a.name), containers.get(a.name),
                                                              host, report=report, kind=kind, ready_timeout=timeout),
                                limit=SIDE_BY_SIDE, name="robocore-start")
    finally:
        client.close()
        if local is not None:
            local.close()
    return outcome


def _deliver(client: docker.DockerClient, local: docker.DockerClient, specs: Sequence[ContainerSpec], project: Project,
             host: Host, outcome: HostOutcome, *, report: Reporter) -> dict[str, str]:
    """Put robocore's images on a remote host (pulled from the registry, or streamed from this machine); a
    release's images (``run --tag``) are pulled by the host for its own arch. Returns the image IDs the
    delivery read on the way (reference -> ID), so that they are not asked for again."""
    images = _robocore_images(specs, project)
    from robocore.adapters.image_delivery import ensure_images, pull_for_arch

    deliveries = ensure_images(client, images, registry=project.robot.registry, progress=report.human,
                               label=host.name, source=local)
    released = sorted({s.image for s in specs if is_released(project.robot.registry, s.image)})
    deliveries.update(pull_for_arch(client, released, arch=host.arch.value, label=host.name))
    outcome.notes += [str(d) for d in deliveries.values() if getattr(d, "action", "present") != "present"]
    return {ref: d.image_id for ref, d in deliveries.items() if getattr(d, "image_id", "")}


def _check_name_conflicts(client: docker.DockerClient, specs: Sequence[ContainerSpec], ours: dict[str, Any],
                          host: Host) -> None:
    from docker.errors import NotFound

    for spec in specs:
        if spec.name in ours:
            continue
        try:
            other = client.containers.get(spec.name)
        except NotFound:
            continue
        if other.labels.get(naming.LABEL_PROJECT) != spec.project:
            raise DockerError(f"host {host.name}: a container named {spec.name} exists and was not made by robocore "
                              f"for this project", hint=f"remove it (`docker rm -f {spec.name}`) or rename the project")
        other.remove(force=True)  # ours, but with another role (e.g. a leftover): recreate it


def apply_action(client: docker.DockerClient, action: Action, spec: ContainerSpec | None, container: Any, host: Host, *,
           report: Reporter, kind: discovery.Discovery, ready_timeout: float) -> None:
    """Carry out one planned ``action`` on ``host``: remove, keep, start, or (re)create the container of ``spec``.
    A replaced node's container gets ``kind``'s successor environment (the next client profile after its
    predecessor's) and keeps the spec's labels, so a later run keeps it; a created discovery server is waited for
    (``ready_timeout``). Docker's refusals become one :class:`DockerError` line, with a hint where one helps."""
    from docker.errors import APIError, NotFound
    from rich.markup import escape

    def say(text: str) -> None:
        report.info(f"[bold]{host.name}[/]: {escape(text)}", markup=True)

    try:
        if action.verb == "remove":
            with contextlib.suppress(NotFound):  # gone meanwhile: removed all the same
                container.remove(force=True)
            say(f"removed {action.name} ({action.reason})")
        elif action.verb == "keep":
            return
        elif action.verb == "start":
            container.start()
            say(f"started {action.name}")
        else:
            assert spec is not None
            kwargs = spec.docker_kwargs()
            if action.verb == "replace":
                if spec.role != ROLE_DISCOVERY:  # the hash label stays the spec's: a later run keeps it
                    kwargs["environment"] = kind.successor_environment(environment_of(container),
                                                                         kwargs["environment"])
                with contextlib.suppress(NotFound):  # gone meanwhile: made anew all the same
                    container.remove(force=True)
            created = client.containers.create(**kwargs)
            created.start()
            if spec.role == ROLE_DISCOVERY:
                wait_server_ready(created, spec, host, kind.readiness, ready_timeout)
            say(f"{'recreated' if action.verb == 'replace' else 'created'} {action.name}"
                + (f" ({action.reason})" if action.reason else ""))
    except APIError as exc:
        hint = None
        text = short_error(exc)
        if "bind source path does not exist" in text:
            hint = "run `robocore sync` first" if not host.is_local else "run `robocore build` first"
        elif spec is not None and spec.docker_kwargs().get("oom_score_adj", 0) < 0 and "child's PID" in text:
            hint = (f"resources.priority: critical lowers the container's OOM score, which host {host.name}'s Docker "
                    "may not do (it lacks CAP_SYS_RESOURCE, as in some sandboxes); remove the priority there")
        raise DockerError(f"host {host.name}: {action.verb} {action.name} failed: {text}", hint=hint) from None


def environment_of(container: Any) -> dict[str, str]:
    """A container's environment as Docker reports it (``NAME=value`` lines), as a mapping."""
    lines = (container.attrs.get("Config") or {}).get("Env") or []
    return dict(line.partition("=")[::2] for line in lines if isinstance(line, str))


SERVER_READY_TIMEOUT = 20.0


def wait_server_ready(container: Any, spec: ContainerSpec, host: Host, check: discovery.ReadinessCheck,
                      timeout: float = SERVER_READY_TIMEOUT) -> None:
    """Wait until a discovery server container serves, as ``check`` (its discovery kind's readiness) reads its
    log and state; DockerError with the reason (its last error line) if it fails or ``timeout`` passes first."""
    import time

    deadline = time.monotonic() + timeout
    while True:
        text = container.logs(tail=50).decode(errors="replace")
        container.reload()
        restarts = int(container.attrs.get("RestartCount", 0))
        state = discovery.ServerState(container.status, restarts, timed_out=time.monotonic() > deadline)
        verdict = check(text, state)
        if verdict.ready:
            return
        if verdict.failed:
            raise DockerError(f"host {host.name}: discovery server {spec.service} did not start ({container.status}): "
                              f"{verdict.reason}", hint=verdict.hint)
        time.sleep(0.3)


def run(options: Options, *, host: str | None, tag: str | None) -> None:
    """(Re)start containers on hosts: discovery servers first, then components; idempotent."""
    project = options.load()
    hosts = select_hosts(project, host)
    if not options.dry_run:
        write_compose_files(project, tag=tag)

    def work(h: Host, servers_restarted: bool = False, server_start: datetime | None = None) -> HostOutcome:
        # a newly synced release restarts its component; the history is what rollback returns to
        specs = with_synced_release(project, h, host_specs(project, h.name, tag=tag))
        if not specs and not host and not history(project, h.name):
            # nothing to start and nothing this project could have left there: an offline spare
            # machine in robot.yaml must not fail the run
            return HostOutcome(h.name, notes=[NOT_CONTACTED])
        from robocore.commands.support.displays import prepare_host_displays  # cookies of gui: true components

        display_notes = prepare_host_displays(project, h, dry_run=options.dry_run)
        outcome = deploy_host(project, h, specs, dry_run=options.dry_run, report=options.report,
                              servers_restarted=servers_restarted, server_start=server_start)
        outcome.notes += display_notes
        if not options.dry_run:
            record_run(project, h, tag)
        return outcome

    kind = discovery.for_robot(project.robot)
    if kind.nodes_register_once:
        # the servers' hosts first: nodes elsewhere start once their server serves, and restart if it restarted
        server_hosts = {s.host for s in kind.servers()}
        results, failures = for_each_host([h for h in hosts if h.name in server_hosts], work)
        names = {naming.discovery_container_name(project.name, s.index) for s in kind.servers()}
        restarted = any(servers_started(out.actions, names) for out in results.values())
        others = [h for h in hosts if h.name not in server_hosts]
        started = None if restarted or not others or options.dry_run else _servers_started_at(project, kind)
        rest, rest_failures = for_each_host(others, lambda h: work(h, servers_restarted=restarted,
                                                                   server_start=started))
        results.update(rest)
        failures.update(rest_failures)
    else:
        results, failures = for_each_host(hosts, work)
    outcomes = [results.get(h.name) or HostOutcome(h.name, ok=False, error=failures[h.name].lines()[0])
                for h in hosts]
    options.report.add(*outcomes)
    _report(options.report, outcomes, dry_run=options.dry_run)
    if failures:
        raise GroupError(failures, list(results))


def _servers_started_at(project: Project, kind: discovery.Discovery) -> datetime | None:
    """When the robot's running discovery servers last started (each read on its own host), None when none
    runs or a host cannot be asked: nodes elsewhere that started before it are not registered with it."""
    from docker.errors import DockerException

    times: list[str] = []
    for server in kind.servers():
        try:
            client = connect(project, project.robot.host(server.host))
        except RobocoreError:
            continue
        try:
            container = client.containers.get(naming.discovery_container_name(project.name, server.index))
            if container.status == "running":
                times.append(_started_at(container))
        except (DockerException, OSError):  # a server that cannot be read dates nothing
            continue
        finally:
            client.close()
    return latest_start(times)


def _report(report: Reporter, outcomes: Sequence[HostOutcome], *, dry_run: bool) -> None:
    """For people: a dry run's actions one line each; a table of what each host did (or why it failed)."""
    failed = any(not out.ok for out in outcomes)
    if report.quiet and not failed:
        return
    from rich.markup import escape
    from rich.table import Table

    if dry_run:
        for out in outcomes:
            for action in out.actions:
                reason = f" ({action.reason})" if action.reason else ""
                verb = "" if action.verb == UNKNOWN else "keep " if action.verb == "keep" else f"would {action.verb} "
                report.out(f"{out.host}: {verb}{action.name}{reason}")
            for note in out.notes:
                report.out(f"{out.host}: {note}")
        if not failed:
            return
    title = "would do" if dry_run else "run"
    table = Table(title=f"robocore {title}", title_justify="left")
    for column in ("host", "result", "created", "replaced", "started", "kept", "removed", "detail"):
        table.add_column(column)
    for out in outcomes:
        if not out.ok:
            table.add_row(out.host, "[red]failed[/]", "", "", "", "", "", escape(out.error or ""))
            continue
        detail = escape("; ".join(out.notes))
        table.add_row(out.host, "[green]ok[/]", *(str(out.count(v)) for v in ("create", "replace", "start", "keep",
                                                                               "remove")), detail)
    report.table(table)
