"""sync: install trees and runtime files to each remote host, atomically.

For every component on a remote host: its colcon install tree, the DDS profiles and the host's
compose file go to ``<mount_root>/<component>/releases/<id>/`` and ``current`` is switched to
it only once the copy is complete (see :mod:`robocore.plan.sync`), all under the host's sync
lock, in one ssh session per host plus one rsync per changed component. Hosts are synced in
parallel; a host that fails is named and the others still get their files. Components on this
machine use the build output in place: nothing is copied.

What each host received is recorded (release id and a digest of the trees per component, see
:mod:`robocore.commands.support.state`); ``run`` uses the release id to restart a container whose files
changed.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import shlex
import time
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import ClassVar

from robocore.adapters import rsync, ssh
from robocore.commands.support.arch_checks import refuse_foreign_install
from robocore.commands.support.context import Options
from robocore.commands.support.hosts import for_each_host, lock_holder, lock_refused, select_hosts
from robocore.commands.support.reporting import Reporter
from robocore.commands.support.state import read_build_state, read_synced, write_synced
from robocore.config.model import Component, Host, read_only_project_path
from robocore.errors import GroupError, HostError, UnsafePath, UsageError
from robocore.files import make_folder, read_own_file, refuse_links_leaving, remove_tree
from robocore.plan import gui, layout, remote_build
from robocore.plan import sync as plan
from robocore.project import Project
from robocore.ui import human_size


@dataclass(frozen=True)
class ComponentResult:
    """What one component's sync did."""

    kind: ClassVar[str] = "sync"
    component: str
    host: str
    release: str
    changed: bool
    sent: int
    received: int
    files: int
    seconds: float


@dataclass(frozen=True)
class PlannedSync:
    """What a sync of one component would run (a dry run): the host's session and the component's rsync."""

    kind: ClassVar[str] = "sync_plan"
    component: str
    host: str
    root: str
    session: list[str]
    rsync: list[str]


def plan_host(project: Project, host: Host, *, dry_run: bool = False) -> list[plan.ComponentSync]:
    """The sync items of ``host`` (empty for this machine), or a UsageError if inputs are missing.

    What is sent must stay in the project: a symlink in an install tree or a read-only volume that leads
    out of it is refused (UnsafePath) unless robot.yaml allows it, since rsync copies what such links
    point to. ``dry_run`` writes nothing (the folder of links to the read-only volumes is not made).
    """
    if host.is_local:
        return []
    robot = project.robot
    dds_dir = project.dds_dir
    compose = project.compose_file(host.name)
    items = []
    for comp in robot.components_on(host.name):
        sources: list[plan.Source] = []
        on_host: tuple[PurePosixPath | None, str] = (None, "")
        if comp.has_workspace and remote_build.builds_on_host(host):
            on_host = _built_on_host(project, host, comp)
        elif comp.has_workspace:
            install = project.build_dir(comp.name) / "install"
            if not install.is_dir():
                raise UsageError(f"component {comp.name}: no install tree at {install}",
                                 hint=f"run `build --component {comp.name}` first")
            refuse_links_leaving(install, project.root, what=f"the install tree of component {comp.name}, "
                                 f"sent to host {host.name}")
            refuse_foreign_install(install, host, comp.name)
            sources.append(plan.Source(install, "install"))
        if not dds_dir.is_dir() or not compose.is_file():
            raise UsageError(f"host {host.name}: {compose if not compose.is_file() else dds_dir} is missing",
                             hint="run `stage` (or `stage --refresh`) first: it writes compose files and DDS profiles")
        sources.append(plan.Source(dds_dir, "dds"))
        sources.append(plan.Source(compose, compose.name))
        if gui.needs_password(comp):  # rsync -a keeps the modes: the folder 0700, the password 0600
            if not read_own_file(gui.password_file(project)):  # a link there is no password, never followed
                raise UsageError(f"component {comp.name}: no VNC password at {gui.password_file(project)}",
                                 hint="run `stage` (or `stage --refresh`) first: it makes the desktop's password")
            sources.append(plan.Source(project.desktop_dir, gui.PASSWORD_FOLDER))
        files = _project_files(project, host, comp, dry_run=dry_run)
        if files is not None:
            sources.append(files)
        items.append(plan.ComponentSync(
            component=comp.name, host=host.name, root=layout.component_root(host, comp.name),
            sources=tuple(sources), compose_name=compose.name, install_on_host=on_host[0], host_build_id=on_host[1],
        ))
    return items


def _built_on_host(project: Project, host: Host, comp: Component) -> tuple[PurePosixPath, str]:
    """The install tree ``comp``'s last build left on ``host`` (``builds_here``) and that build's id, or a
    UsageError when it was not built there."""
    state = read_build_state(project.host_build_state_file(comp.name))
    where = remote_build.host_build(host, comp.name)
    if state.get("host") != host.name or state.get("root") != str(where.root) or not state.get("build"):
        raise UsageError(f"component {comp.name}: not built on host {host.name} yet (builds_here: true)",
                         hint=f"run `build --component {comp.name}` first")
    return where.install, str(state["build"])


def _project_files(project: Project, host: Host, comp: Component, *, dry_run: bool = False) -> plan.Source | None:
    """The read-only project volumes of ``comp`` as one source: a folder of symlinks to them, kept in
    ``.robocore/sync/files/<host>/<component>/files`` and made anew whenever the set of links changes
    (not in a dry run, which writes nothing)."""

    wanted = [(i, rel) for i, v in enumerate(comp.volumes) if (rel := read_only_project_path(v)) is not None]
    allowed = bool(getattr(comp, "allow_outside_project", False))  # robot.yaml's opt-in, for symlinks only
    farm = project.sync_links_dir(host.name, comp.name) / layout.FILES
    links: dict[str, Path] = {}
    for index, rel in wanted:
        real = (project.root / rel).resolve()
        if not real.exists():
            raise UsageError(f"component {comp.name}: volumes[{index}]: {project.root / rel} does not exist",
                             hint=f"create it, or remove the volume: sync copies it to {host.name}")
        if rel == ".." or rel.startswith("../"):
            raise UnsafePath(f"component {comp.name}: volumes[{index}]: {rel} is outside the project folder "
                             f"({real}); sync would send it to host {host.name}",
                             hint="move it into the project, or mount it from the host's own file system")
        if not real.is_relative_to(project.root) and not allowed:  # through a symlink
            raise UnsafePath(f"component {comp.name}: volumes[{index}]: {rel} leads to {real}, outside the "
                             f"project folder; sync would send it to host {host.name}",
                             hint="move it into the project, or set allow_outside_project: true on the component")
        refuse_links_leaving(project.root / rel, project.root, allowed=allowed,
                             what=f"read-only volume {comp.volumes[index]!r} of component {comp.name}, "
                             f"sent to host {host.name}")
        links[rel] = real
    if dry_run:
        return plan.Source(farm, layout.FILES, follow=True) if links else None
    if _farm_links(farm) != links:  # made anew only when it changes: its folders' times are in the digest
        remove_tree(farm, ignore_errors=True)
        for rel, real in links.items():
            folder = farm
            for part in ("", *Path(rel).parent.parts):  # sent as they are to the host and read there: 0755
                folder = folder / part if part else folder
                make_folder(folder, shared=True)
            (farm / rel).symlink_to(real)
    return plan.Source(farm, layout.FILES, follow=True) if links else None


def _farm_links(farm: Path) -> dict[str, Path]:
    found: dict[str, Path] = {}
    for dirpath, dirnames, filenames in os.walk(farm):
        for name in [*dirnames, *filenames]:
            path = Path(dirpath) / name
            if path.is_symlink():
                found[path.relative_to(farm).as_posix()] = Path(os.readlink(path))
    return found


def sync(options: Options, *, host: str | None) -> None:
    """Copy install trees and runtime files to remote hosts; only what changed; atomic per component."""
    project = options.load()
    report = options.report
    hosts = select_hosts(project, host)
    plans = {h.name: plan_host(project, h, dry_run=options.dry_run) for h in hosts}
    if options.dry_run:
        _dry_run(report, hosts, plans)
        return
    remote = [h for h in hosts if plans[h.name]]
    for h in hosts:
        if h.is_local:
            report.info(f"{h.name}: this machine, components use the build output in place (nothing to copy)")
        elif not plans[h.name]:
            report.info(f"{h.name}: no components")
    if not remote:
        return
    rsync.require_rsync()
    ssh.require_ssh()
    results, failures = for_each_host(remote, lambda h: sync_host(project, h, plans[h.name]))
    rows = [r for name in sorted(results) for r in results[name]]
    report.add(*rows)
    if not options.quiet:
        _print_table(report, rows)
    if failures:
        raise GroupError(failures, sorted(results))


def sync_host(project: Project, host: Host, items: list[plan.ComponentSync]) -> list[ComponentResult]:
    """Sync every item of one host, one release id for all, and record what the host now runs.

    The host's side is one ssh session (:data:`robocore.plan.sync.SESSION_SCRIPT`): it takes the
    host's sync lock and reports each component's state, waits while rsync copies the components
    whose tree may differ (one rsync each), then releases, discards or keeps each copy.
    """
    refused = functools.partial(lock_refused, host, busy="another sync to this host is in progress", again="sync",
                                locks="syncs")
    with ssh.hold(host, plan.session_argv(host.deploy_root, lock_holder(), items), ready=plan.LOCKED,
                  what="taking the sync lock", refused=refused) as session:
        return _sync_locked(project, host, items, session)


def _sync_locked(project: Project, host: Host, items: list[plan.ComponentSync],
                 session: ssh.Session) -> list[ComponentResult]:
    release_id = plan.new_release_id()
    rsh = ssh.rsh_command(host)
    recorded = read_synced(project, host.name)
    start = time.monotonic()
    digests = [_tree_digest(item) for item in items]
    try:
        preps = plan.parse_prepare(session.greeting, len(items))
    except ValueError as exc:
        raise HostError(f"host {host.name} ({host.ip}): the sync session answered unexpectedly: {exc}",
                        hint="is a POSIX sh the login shell's sh there?") from None
    steps: list[str] = []
    stats: dict[str, plan.RsyncStats] = {}
    seconds: dict[str, float] = {}
    for item, digest, prep in zip(items, digests, preps, strict=True):
        previous = recorded.get(item.component, {})
        current = prep.get("current", "")
        same_release = bool(current) and current == f"{plan.RELEASES}/{previous.get('release', '')}"
        resuming = prep.get("staging") == "1"  # an interrupted copy: its content is unknown
        if same_release and not resuming and digest == previous.get("digest"):
            stats[item.component] = plan.RsyncStats()  # quick check: nothing to send
            steps.append(plan.KEEP)
            continue
        t = time.monotonic()
        stats[item.component] = rsync.run(host, plan.rsync_argv(item, host, rsh))
        if item.install_on_host is not None:  # built there: the host copies its own tree into the release
            stats[item.component] = _add(stats[item.component], _release_host_install(host, item))
        seconds[item.component] = time.monotonic() - t
        changed = stats[item.component].changed or resuming or not same_release or digest != previous.get("digest")
        steps.append(plan.RELEASE if changed else plan.DISCARD)
    session.finish(plan.finish_line(release_id, steps), done=plan.DONE, what="switching to the new release")
    results = []
    for item, digest, prep, step in zip(items, digests, preps, steps, strict=True):
        is_new = step == plan.RELEASE
        release = release_id if is_new else prep.get("current", "").removeprefix(f"{plan.RELEASES}/")
        recorded[item.component] = {"release": release, "digest": digest}
        st = stats[item.component]
        results.append(ComponentResult(
            component=item.component, host=host.name, release=release, changed=is_new, sent=st.sent,
            received=st.received, files=st.files, seconds=seconds.get(item.component, 0.0),
        ))
    write_synced(project, host.name, recorded)
    if results:
        total = time.monotonic() - start
        results = [dataclasses.replace(r, seconds=round(total, 2)) for r in results]
    return results


def _release_host_install(host: Host, item: plan.ComponentSync) -> plan.RsyncStats:
    """Copy the install tree built on ``host`` into ``item``'s staging there (rsync on the host itself)."""
    argv = remote_build.release_install_argv(remote_build.host_build(host, item.component))
    try:
        proc = ssh.run(host, argv, timeout=3600)
    except HostError as exc:
        raise HostError(f"host {host.name}: cannot release the install tree built there for {item.component}: "
                        f"{exc.message}", hint=f"run `build --component {item.component}` again") from None
    return plan.parse_stats(proc.stdout.decode(errors="replace"))


def _add(a: plan.RsyncStats, b: plan.RsyncStats) -> plan.RsyncStats:
    return plan.RsyncStats(**{f.name: getattr(a, f.name) + getattr(b, f.name) for f in dataclasses.fields(a)})


def _tree_digest(item: plan.ComponentSync) -> str:
    rows: list[tuple[str, int, int, int, str]] = []
    if item.install_on_host is not None:
        rows.append((f"{item.install_on_host} on the host", 0, 0, 0, item.host_build_id))
    for source in item.sources:
        for path in _walk(source.path, follow=source.follow):
            st = path.stat() if source.follow else path.lstat()
            target = os.readlink(path) if path.is_symlink() and not source.follow else ""
            rel = f"{source.name}/{path.relative_to(source.path)}" if path != source.path else source.name
            rows.append((rel, st.st_size, st.st_mtime_ns, st.st_mode, target))
    return plan.manifest_digest(rows)


def _walk(root: Path, *, follow: bool = False) -> list[Path]:
    if not root.is_dir() or (root.is_symlink() and not follow):
        return [root]
    found = [root]
    for dirpath, dirnames, filenames in os.walk(root, followlinks=follow):
        base = Path(dirpath)
        found.extend(base / d for d in dirnames)
        found.extend(base / f for f in filenames)
    return found


def _dry_run(report: Reporter, hosts: list[Host], plans: dict[str, list[plan.ComponentSync]]) -> None:
    """The plan of a sync: per remote host its one session and one rsync per component; nothing runs."""
    for h in hosts:
        if h.is_local:
            report.out(f"# {h.name}: this machine, nothing to copy")
            continue
        rsh = ssh.rsh_command(h)
        items = plans[h.name]
        if not items:
            continue
        session = ssh.ssh_argv(h, plan.session_argv(h.deploy_root, lock_holder(), items))
        report.out(f"# {h.name}: " + ", ".join(f"{i.component} -> {i.root}" for i in items))
        report.out(f"# one session (holding flock on {h.deploy_root}/{plan.LOCK_FILE} there) prepares, waits "
                   f"for the rsyncs, then releases each changed copy")
        report.out(shlex.join(session))
        for item in items:
            argv = plan.rsync_argv(item, h, rsh)
            report.out(shlex.join(argv))
            if item.install_on_host is not None:
                report.out(f"# {item.component} was built on {h.name}: its install tree is copied there")
                report.out(shlex.join(ssh.ssh_argv(h, remote_build.release_install_argv(
                    remote_build.host_build(h, item.component)))))
            report.add(PlannedSync(component=item.component, host=h.name, root=str(item.root), session=session,
                                   rsync=argv))
        steps = " ".join(plan.RELEASE for _ in items)
        report.out(f"# then, on that session's stdin: {plan.new_release_id()} {steps}")


def _print_table(report: Reporter, rows: list[ComponentResult]) -> None:
    from rich.table import Table

    table = Table(title="sync")
    for col in ("host", "component", "release", "changed", "sent", "received", "files", "host time"):
        table.add_column(col, justify="right" if col in {"sent", "received", "files", "host time"} else "left",
                         no_wrap=col == "release")
    for r in rows:
        table.add_row(r.host, r.component, r.release, "yes" if r.changed else "no", human_size(r.sent),
                      human_size(r.received), str(r.files), f"{r.seconds:.1f}s")
    total = sum(r.sent for r in rows)
    table.caption = f"{human_size(total)} sent in total"
    report.table(table)
