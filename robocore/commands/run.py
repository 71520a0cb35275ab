"""run and down: create, replace or remove each host's containers.

``run`` compares each planned :class:`~robocore.plan.containers.ContainerSpec` with what the
host runs: a container whose spec hash label and image ID match is left alone, a changed
one is recreated alone, a missing one is created, and robocore containers of this project
that are no longer planned on that host are removed. Hosts are handled in parallel; a host
that fails (unreachable, missing image, ...) does not stop the others, and the command ends
with a per-host summary and a :class:`~robocore.errors.GroupError`.
"""

from __future__ import annotations

import contextlib
import json
import sys
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from robocore.adapters.docker_hosts import is_connection_error
from robocore.commands.context import DRY_RUN_UNKNOWN, Options
from robocore.config.model import Host
from robocore.errors import DockerError, GroupError, HostError, RobocoreError, UsageError
from robocore.plan import dds, naming
from robocore.plan.containers import (
    ROLE_COMPONENT,
    ROLE_DISCOVERY,
    ContainerSpec,
    discovery_state_volume,
    host_specs,
)
from robocore.project import Project
from robocore.ui import console, stdout

if TYPE_CHECKING:
    import docker

T = TypeVar("T")

#: Roles of the containers ``run`` and ``down`` manage (dev shells and build containers are left alone).
MANAGED_ROLES = (ROLE_COMPONENT, ROLE_DISCOVERY)
#: Verb of a dry run's action: what the host runs now is not known.
UNKNOWN = "unknown"
#: Note of a host ``run`` leaves alone: nothing planned there, and no run of this project ever reached it.
NOT_CONTACTED = "nothing planned, never deployed here: not contacted"
#: Seconds a host gets to answer before it is reported unreachable.
HOST_CONNECT_TIMEOUT = 8
#: Seconds each Docker API call to a host may take.
CONNECT_API_TIMEOUT = 300


# --------------------------------------------------------------------------- hosts in parallel


def select_hosts(project: Project, host: str | None) -> list[Host]:
    """``--host NAME`` (checked), else every host of the robot."""
    return [project.host(host)] if host else list(project.robot.hosts)


def connect(project: Project, host: Host, *, timeout: int = CONNECT_API_TIMEOUT) -> docker.DockerClient:
    """The Docker client of ``host`` (HostError naming the host when it cannot be reached)."""
    from robocore.adapters.docker_hosts import client_for

    return client_for(host, timeout, project_root=project.root, connect_timeout=HOST_CONNECT_TIMEOUT)


def prefetch_connections(project: Project) -> None:
    """Start :func:`connect`'s connection to every ssh host that runs something, in the background."""
    from robocore.adapters.docker_hosts import prefetch

    for host in project.robot.hosts_in_use():
        prefetch(host, CONNECT_API_TIMEOUT, connect_timeout=HOST_CONNECT_TIMEOUT)


def for_each_host(hosts: Sequence[Host], work: Callable[[Host], T]) -> tuple[dict[str, T], dict[str, RobocoreError]]:
    """Run ``work(host)`` for every host in parallel; return (results, failures) by host name.

    Docker and network errors become a HostError of that host; other exceptions are bugs and
    are raised once every host has finished.
    """
    results: dict[str, T] = {}
    failures: dict[str, RobocoreError] = {}
    bugs: list[BaseException] = []
    if not hosts:
        return results, failures
    with ThreadPoolExecutor(max_workers=len(hosts), thread_name_prefix="robocore-host") as pool:
        futures = {h.name: pool.submit(work, h) for h in hosts}
        for name, future in futures.items():
            try:
                results[name] = future.result()
            except RobocoreError as error:
                failures[name] = error
            except Exception as exc:
                if is_connection_error(exc):
                    failures[name] = HostError(f"host {name}: {_short(exc)}")
                else:
                    bugs.append(exc)
    if bugs:
        raise bugs[0]
    return results, failures


def _short(exc: BaseException) -> str:
    explanation = getattr(exc, "explanation", None)
    text = str(explanation or exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


# --------------------------------------------------------------------------- pure decisions


@dataclass(frozen=True)
class Existing:
    """A managed container found on a host."""

    name: str
    spec_hash: str | None
    image_id: str
    running: bool
    role: str


@dataclass(frozen=True)
class Action:
    """One thing ``run`` does (or would do) to one container."""

    verb: str  # create | replace | start | keep | remove
    name: str
    reason: str = ""


def decide(specs: Sequence[ContainerSpec], existing: Sequence[Existing], image_ids: dict[str, str]) -> list[Action]:
    """What to do on one host: obsolete containers are removed first, then specs in order.

    ``image_ids`` maps each spec's image reference to the image ID it should run (a spec
    whose image is not in it is compared by spec hash only).
    """
    found = {e.name: e for e in existing}
    planned = {s.name for s in specs}
    actions = [Action("remove", e.name, "no longer planned on this host") for e in existing if e.name not in planned]
    for spec in specs:
        current = found.get(spec.name)
        wanted_image = image_ids.get(spec.image)
        if current is None:
            actions.append(Action("create", spec.name))
        elif current.spec_hash != spec.spec_hash:
            actions.append(Action("replace", spec.name, "configuration changed"))
        elif wanted_image is not None and current.image_id != wanted_image:
            actions.append(Action("replace", spec.name, "new image"))
        elif not current.running:
            actions.append(Action("start", spec.name, "was stopped"))
        else:
            actions.append(Action("keep", spec.name))
    return actions


# --------------------------------------------------------------------------- run


@dataclass
class HostOutcome:
    """What happened on one host."""

    host: str
    actions: list[Action] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def count(self, verb: str) -> int:
        """How many actions have ``verb``."""
        return sum(1 for a in self.actions if a.verb == verb)


def managed_containers(client: docker.DockerClient, project: str) -> list[Any]:
    """This project's component and discovery containers on a host (running or not)."""
    found = client.containers.list(all=True, filters={"label": f"{naming.LABEL_PROJECT}={project}"})
    return [c for c in found if c.labels.get(naming.LABEL_ROLE) in MANAGED_ROLES]


def _existing(container: Any) -> Existing:
    return Existing(
        name=container.name,
        spec_hash=container.labels.get(naming.LABEL_SPEC),
        image_id=container.attrs.get("Image", ""),
        running=container.status == "running",
        role=container.labels.get(naming.LABEL_ROLE, ""),
    )


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
    own = {c.image for c in project.robot.components if c.image}
    return sorted({s.image for s in specs if s.image not in own})


def _image_id(client: docker.DockerClient, ref: str) -> str | None:
    from docker.errors import ImageNotFound

    try:
        return str(client.images.get(ref).id)
    except ImageNotFound:
        return None


def _image_ids(
    client: docker.DockerClient, local: docker.DockerClient | None, specs: Sequence[ContainerSpec], project: Project,
    host: Host, *, dry_run: bool,
) -> dict[str, str]:
    """Image reference -> ID the host must run; robocore images must exist (on this machine for remote hosts)."""
    ids: dict[str, str] = {}
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
                                  f"{_short(exc)}") from None
            image_id = _image_id(client, spec.image)
        if image_id is None and spec.image in ours:
            step = "prepare-base" if spec.role == ROLE_DISCOVERY else "stage"
            raise DockerError(f"host {host.name}: image {spec.image} does not exist",
                              hint=f"run `robocore {step}` first")
        if image_id is not None:
            ids[spec.image] = image_id
    return ids


#: Label of a local component's container: the state of the build it runs (see with_local_build).
LABEL_BUILD = "dev.robocore.build"


def with_local_build(project: Project, host: Host, specs: Sequence[ContainerSpec]) -> list[ContainerSpec]:
    """Add the state of each local component's last build to its spec's labels.

    Local containers mount ``.robocore/build/<c>/install`` in place, so a rebuild changes
    nothing in the spec; without this label ``run`` would keep the container on the code it
    loaded at start. The build writes a small state file (package hashes) after each success.
    """
    import dataclasses
    import hashlib

    if not host.is_local:
        return list(specs)
    from robocore.commands.build import BUILD_STATE

    out = []
    for spec in specs:
        if spec.role == ROLE_COMPONENT:
            try:
                state = (project.build_dir(spec.service) / BUILD_STATE).read_bytes()
            except OSError:
                state = b""
            if state:
                digest = hashlib.sha256(state).hexdigest()[:16]
                spec = dataclasses.replace(spec, extra_labels=(*spec.extra_labels, (LABEL_BUILD, digest)))
        out.append(spec)
    return out


def deploy_host(project: Project, host: Host, specs: Sequence[ContainerSpec], *, dry_run: bool,
                quiet: bool) -> HostOutcome:
    """Bring one host to its planned containers (or, with ``dry_run``, say what that would take from what
    is known here: the host is not contacted, so what it runs now is unknown)."""
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
    try:
        if not host.is_local:
            from robocore.adapters.docker_hosts import local_client

            local = local_client(timeout=600)  # also streams images (docker save) to the host
            if not dry_run:
                _deliver(client, local, _robocore_images(specs, project), project, host, outcome, quiet=quiet)
        image_ids = _image_ids(client, local, specs, project, host, dry_run=dry_run)
        containers = {c.name: c for c in managed_containers(client, project.name)}
        _check_name_conflicts(client, specs, containers, host)
        actions = decide(specs, [_existing(c) for c in containers.values()], image_ids)
        outcome.actions = actions
        if dry_run:
            return outcome
        by_name = {s.name: s for s in specs}
        for action in actions:
            _apply(client, action, by_name.get(action.name), containers.get(action.name), host, quiet=quiet)
    finally:
        client.close()
        if local is not None:
            local.close()
    return outcome


def _deliver(client: docker.DockerClient, local: docker.DockerClient, images: list[str], project: Project,
             host: Host, outcome: HostOutcome, *, quiet: bool) -> None:
    try:
        from robocore.adapters.image_delivery import ensure_images
    except ImportError:  # image delivery not available: the host must already have the images
        return
    deliveries = ensure_images(client, images, registry=project.robot.registry, progress=not quiet, label=host.name,
                               source=local)
    outcome.notes += [str(d) for d in deliveries.values() if getattr(d, "action", "present") != "present"]


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


def _apply(client: docker.DockerClient, action: Action, spec: ContainerSpec | None, container: Any, host: Host, *,
           quiet: bool) -> None:
    from docker.errors import APIError
    from rich.markup import escape

    def say(text: str) -> None:
        if not quiet:
            console().print(f"[bold]{host.name}[/]: {escape(text)}")

    try:
        if action.verb == "remove":
            container.remove(force=True)
            say(f"removed {action.name} ({action.reason})")
        elif action.verb == "keep":
            return
        elif action.verb == "start":
            container.start()
            say(f"started {action.name}")
        else:
            assert spec is not None
            if action.verb == "replace":
                container.remove(force=True)
            created = client.containers.create(**spec.docker_kwargs())
            created.start()
            if spec.role == ROLE_DISCOVERY:
                wait_server_ready(created, spec, host)
            say(f"{'recreated' if action.verb == 'replace' else 'created'} {action.name}"
                + (f" ({action.reason})" if action.reason else ""))
    except APIError as exc:
        hint = None
        text = _short(exc)
        if "bind source path does not exist" in text:
            hint = "run `robocore sync` first" if not host.is_local else "run `robocore build` first"
        raise DockerError(f"host {host.name}: {action.verb} {action.name} failed: {text}", hint=hint) from None


#: What a discovery server container logs once it serves (Fast DDS 2.x, 3.x) or while it holds after a restart.
_SERVER_READY = ("Server is running", "Server started", "robocore: discovery server restarted")
SERVER_READY_TIMEOUT = 20.0


def wait_server_ready(container: Any, spec: ContainerSpec, host: Host, timeout: float = SERVER_READY_TIMEOUT) -> None:
    """Wait until a discovery server container serves; DockerError with its last log line if it stops instead.

    The usual cause is another server (another project) holding the same UDP port on that host.
    """
    import re
    import time

    deadline = time.monotonic() + timeout
    while True:
        text = re.sub(r"\x1b\[[0-9;]*m", "", container.logs(tail=50).decode(errors="replace"))
        container.reload()
        restarted = int(container.attrs.get("RestartCount", 0)) > 0  # it already failed once
        if not restarted and any(marker in text for marker in _SERVER_READY):
            return
        if restarted or container.status in {"exited", "dead", "restarting"} or time.monotonic() > deadline:
            lines = [line.strip() for line in text.splitlines() if line.strip()]
            errors = [line for line in lines if "rror" in line or "failed" in line]
            last = (errors or lines or ["no output"])[-1]
            raise DockerError(
                f"host {host.name}: discovery server {spec.service} did not start ({container.status}): {last[-200:]}",
                hint="is another discovery server using its UDP port on that host? "
                "choose another port in robot.yaml (discovery.servers[].port)",
            )
        time.sleep(0.3)


def run(options: Options, *, host: str | None, tag: str | None) -> None:
    """(Re)start containers on hosts: discovery servers first, then components; idempotent."""
    from robocore.commands.composefiles import write_compose_files

    project = options.load()
    hosts = select_hosts(project, host)
    if not options.dry_run:
        write_compose_files(project, tag=tag)

    def work(h: Host) -> HostOutcome:
        from robocore.commands.release import history, record_run  # history for rollback
        from robocore.commands.sync import with_synced_release  # restart on a newly synced release

        specs = with_synced_release(project, h, host_specs(project, h.name, tag=tag))
        if not specs and not host and not history(project, h.name):
            # nothing to start and nothing this project could have left there: an offline spare
            # machine in robot.yaml must not fail the run
            return HostOutcome(h.name, notes=[NOT_CONTACTED])
        from robocore.commands.displays import prepare_host_displays  # cookies of gui: true components

        display_notes = prepare_host_displays(project, h, dry_run=options.dry_run)
        outcome = deploy_host(project, h, specs, dry_run=options.dry_run, quiet=options.quiet)
        outcome.notes += display_notes
        if not options.dry_run:
            record_run(project, h, tag)
        return outcome

    results, failures = for_each_host(hosts, work)
    _report(results, failures, hosts, options, title="would do" if options.dry_run else "run")
    if failures:
        raise GroupError(failures, list(results))


def _report(results: dict[str, HostOutcome], failures: dict[str, RobocoreError], hosts: Sequence[Host],
            options: Options, *, title: str) -> None:
    if options.json:
        payload = {
            h.name: (
                {"ok": True, "actions": [a.__dict__ for a in results[h.name].actions], "notes": results[h.name].notes}
                if h.name in results else {"ok": False, "error": failures[h.name].lines()}
            )
            for h in hosts
        }
        print(json.dumps(payload, indent=2))
        return
    if options.quiet and not failures:
        return
    from rich.markup import escape
    from rich.table import Table

    if options.dry_run:
        for h in hosts:
            out = results.get(h.name)
            for action in out.actions if out else []:
                reason = f" ({action.reason})" if action.reason else ""
                verb = "" if action.verb == UNKNOWN else "keep " if action.verb == "keep" else f"would {action.verb} "
                stdout().print(f"{h.name}: {verb}{action.name}{reason}", markup=False, soft_wrap=True)
            for note in out.notes if out else []:
                stdout().print(f"{h.name}: {note}", markup=False, soft_wrap=True)
        if not failures:
            return
    table = Table(title=f"robocore {title}", title_justify="left")
    for column in ("host", "result", "created", "replaced", "started", "kept", "removed", "detail"):
        table.add_column(column)
    for h in hosts:
        if h.name in failures:
            table.add_row(h.name, "[red]failed[/]", "", "", "", "", "", escape(failures[h.name].lines()[0]))
            continue
        out = results[h.name]
        detail = escape("; ".join(out.notes))
        table.add_row(h.name, "[green]ok[/]", *(str(out.count(v)) for v in ("create", "replace", "start", "keep",
                                                                             "remove")), detail)
    print_table(table)


def print_table(table: Any) -> None:
    """Print a rich table on stdout; off a terminal (logs, CI, pipes) 160 columns wide, not squeezed into 80."""
    out = stdout()
    if out.is_terminal:
        out.print(table)
        return
    from robocore.ui import make_console

    make_console(file=sys.stdout, width=160).print(table)


# --------------------------------------------------------------------------- down


def stop_host(project: Project, host: Host, *, dry_run: bool, quiet: bool, forget_servers: bool) -> HostOutcome:
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
            if not dry_run:
                container.remove(force=True)
                if not quiet:
                    console().print(f"[bold]{host.name}[/]: removed {escape(container.name)}")
        if forget_servers and not dry_run:
            for server in dds.servers(project.robot):
                if server.host != host.name:
                    continue
                with contextlib.suppress(NotFound):
                    client.volumes.get(discovery_state_volume(project.name, server.index)).remove(force=True)
    finally:
        client.close()
    return outcome


def down(options: Options, *, host: str | None) -> None:
    """Stop and remove this project's containers on every host (or ``--host``)."""
    project = options.load()
    hosts = select_hosts(project, host)
    forget = host is None  # every host goes down: the next start of each server is a first start

    def work(h: Host) -> HostOutcome:
        return stop_host(project, h, dry_run=options.dry_run, quiet=options.quiet, forget_servers=forget)

    results, failures = for_each_host(hosts, work)
    if options.dry_run:
        for name, out in results.items():
            for note in out.notes:
                stdout().print(f"{name}: {note}", markup=False, soft_wrap=True)
    elif not options.quiet:
        for name, out in results.items():
            if not out.actions:
                console().print(f"[bold]{name}[/]: nothing to remove")
    if failures:
        raise GroupError(failures, list(results))
