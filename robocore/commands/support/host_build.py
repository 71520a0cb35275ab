"""build on the robot: the components of a host with ``builds_here: true`` are compiled on that host.

For each such component (see :mod:`robocore.plan.remote_build` for the layout on the host): its staged
image is delivered to the host's daemon as ``run`` delivers images (the registry, or ``docker save``
streamed into ``docker load``); under the host's sync lock, the workspace goes there with rsync (deltas
only) and colcon runs in a throw-away container of that image on the host's daemon, with the host's
persistent build/ and install/ folders, so a rebuild is as incremental there as here. Which packages
changed is decided here, from the package hashes of the last successful build on the host, recorded in
``.robocore/build/<component>/.robocore-host-build.json``: an unchanged workspace costs no connection.
The install tree stays on the host; ``sync`` releases it from there.
"""

from __future__ import annotations

import functools
import os
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from robocore.adapters import rsync, ssh
from robocore.commands.support.arch_checks import refuse_daemon_arch
from robocore.commands.support.colcon_output import colcon_listener
from robocore.commands.support.context import DRY_RUN_UNKNOWN
from robocore.commands.support.hosts import connect, lock_refused
from robocore.commands.support.reporting import Outcome, Reporter
from robocore.commands.support.state import read_build_state, write_build_state
from robocore.config.model import Component, Host
from robocore.errors import BuildError, HostError, RobocoreError
from robocore.files import make_folder
from robocore.plan import arches, colcon, naming
from robocore.plan import remote_build as plan
from robocore.plan.sync import LOCK_FILE
from robocore.project import Project

if TYPE_CHECKING:
    import docker


@dataclass(frozen=True)
class HostBuildPlan:
    """What ``build`` does for one component built on its host."""

    component: Component
    host: Host
    image: str  # the staged image, repository:tag
    image_id: str | None  # None: unknown (a dry run contacts no daemon)
    where: plan.HostBuild
    packages: dict[str, str]  # package -> content hash of its folder
    changed: list[str] | None  # None: everything; []: nothing
    reason: str
    ccache: bool = False  # the image has ccache (its cache is kept on the host)
    workers: int = 0  # 0: colcon's default (the host's cores)

    @property
    def argv(self) -> list[str]:
        """The colcon command line run on the host."""
        return colcon.workspace_build_argv(self.changed or (), self.workers or None)


def plan_host_build(project: Project, comp: Component, host: Host, image: str, image_id: str | None,
                    packages: dict[str, str], *, ccache: bool = False) -> HostBuildPlan:
    """Which packages of ``comp`` its host must (re)build, from the last successful build there.

    Everything when there was none, when it was on another host or of another image; nothing when no
    package changed. ``image_id`` None (a dry run) takes the staged image as unchanged and says so.
    """
    where = plan.host_build(host, comp.name)
    before = read_build_state(project.host_build_state_file(comp.name))
    old = before.get("packages") if isinstance(before.get("packages"), dict) else {}
    changed: list[str] | None
    if not before:
        changed, reason = None, "first build"
    elif before.get("host") != host.name or before.get("root") != str(where.root):
        changed, reason = None, f"last built on host {before.get('host')}"
    elif image_id is not None and before.get("image") != image_id:
        changed, reason = None, "image changed"
    elif set(old or {}) != set(packages):
        changed, reason = None, "packages added or removed"
    else:
        changed = sorted(name for name, digest in packages.items() if (old or {}).get(name) != digest)
        reason = f"changed: {', '.join(changed)}" if changed else "up to date"
    if image_id is None and before:
        reason += f"; whether the staged image changed: {DRY_RUN_UNKNOWN}"
    return HostBuildPlan(component=comp, host=host, image=image, image_id=image_id, where=where,
                         packages=packages, changed=changed, reason=f"on host {host.name}: {reason}", ccache=ccache)


def dry_run_steps(build: HostBuildPlan, workspace: Path) -> list[str]:
    """What a build on the host would run, one line each (a dry run prints them)."""
    import shlex

    rsh = ssh.rsh_command(build.host)
    where = build.where
    return [
        f"deliver {build.image} to host {build.host.name}",
        f"hold the lock {build.host.deploy_root}/{LOCK_FILE} on {build.host.name} (as sync does) while:",
        shlex.join(plan.workspace_rsync_argv(workspace, where, build.host, rsh, skip_dirs=_skip_dirs())),
        f"on {build.host.name}'s daemon, in {build.image} with "
        + " ".join(f"{h}:{c}" for h, c in where.mounts(ccache=build.ccache).items()) + ": " + shlex.join(build.argv),
    ]


def _skip_dirs() -> list[str]:
    from robocore.adapters.image_builder import SKIP_DIRS

    return sorted(SKIP_DIRS)


def build_on_host(project: Project, build: HostBuildPlan, workspace: Path, holder: str, report: Reporter,
                  update: Callable[[str, str], None]) -> Outcome:
    """Deliver the image, send the workspace and run colcon on the host (under its lock); record the build."""
    from robocore.adapters.image_delivery import ensure_images

    name = build.component.name
    host = build.host
    start = time.monotonic()
    client = connect(project, host)
    try:
        # the host's daemon must run the host's arch (natively, or emulated with qemu registered there)
        emulated = refuse_daemon_arch(host, str(client.info().get("Architecture", "?"))).emulated
        update(name, f"image to {host.name}")
        ensure_images(client, [build.image], registry=project.robot.registry, progress=False, label=host.name)
        refused = functools.partial(lock_refused, host, busy="a sync or build on this host is in progress",
                                    again="build", locks="builds and syncs")
        with ssh.hold(host, plan.lock_argv(host, holder, build.where), ready=plan.LOCKED,
                      what="taking the host's lock for a build", refused=refused) as session:
            try:
                user = plan.parse_ids(session.greeting)
            except ValueError as exc:
                raise HostError(f"host {host.name} ({host.ip}): the build session answered unexpectedly: {exc}",
                                hint="is a POSIX sh the login shell's sh there?") from None
            update(name, f"workspace to {host.name}")
            rsync.require_rsync()
            rsync.run(host, plan.workspace_rsync_argv(workspace, build.where, host, ssh.rsh_command(host),
                                                      skip_dirs=_skip_dirs()))
            update(name, f"colcon build on {host.name}")
            code, events, other = _colcon(client, project.name, build, user, report, update, emulated=emulated)
            session.finish(plan.finish_line(host.arch.value if code == 0 else None), done=plan.DONE,
                           what="recording the arch of the install tree and releasing the host's lock")
    finally:
        client.close()
    if code != 0:
        failed = [e.package for e in events if e.state == "failed"]
        tail = "\n".join(f"  {line}" for line in other[-20:])
        where = f"{host.name}:{build.where.work}/log/latest_build"
        if failed:
            raise BuildError(f"component {name}: colcon build on host {host.name} failed in package {failed[0]} "
                             f"(log: {where}/{failed[0]})\n{tail}",
                             hint=f"fix it in {build.component.folder}, then run build --component {name}")
        raise BuildError(f"component {name}: colcon build on host {host.name} exited {code}\n{tail}")
    colcon.refuse_unbuilt(name, build.packages, build.changed, events, other, where=f" on host {host.name}")
    record_host_build(project, build)
    return Outcome(what=name, role="build", action="built", reason=build.reason, image_id=build.image_id,
                   seconds=time.monotonic() - start, packages=[e.package for e in events if e.state == "finished"])


def _colcon(client: docker.DockerClient, project_name: str, build: HostBuildPlan, user: str, report: Reporter,
            update: Callable[[str, str], None], *, emulated: bool) -> tuple[int, list[colcon.PackageEvent], list[str]]:
    """colcon build in a throw-away container of the component's image on the host's daemon, as ``user``
    (``emulated``: the daemon's own arch is another one, so the platform is named, as a local build does)."""
    from robocore.adapters.image_builder import run_streaming

    name = build.component.name

    events: list[colcon.PackageEvent] = []
    other: list[str] = []
    on_line = colcon_listener(name, "building", "", events, other, update, report)
    attempts = [build.argv] + ([colcon.workspace_build_argv((), build.workers or None)] if build.changed else [])
    code = 1
    for argv in attempts:
        code = run_streaming(
            client, build.image, argv, user=user, volumes=build.where.mounts(ccache=build.ccache),
            environment=container_env(build), labels=build_labels(project_name, name), on_line=on_line,
            platform=arches.platform(build.host.arch.value) if emulated else None,
        )
        # an image whose colcon lacks colcon-package-selection: build everything instead
        if not (code == 2 and any("--packages-above" in line for line in other[-3:])):
            break
        other.clear()
    return code, events, other


def container_env(build: HostBuildPlan) -> dict[str, str]:
    """The build container's environment on the host: a local build's, without this machine's core count."""
    env = colcon.build_env(1, ccache=build.ccache)
    for key in ("CMAKE_BUILD_PARALLEL_LEVEL", "MAKEFLAGS"):  # the host's own cores, not the dev machine's
        env.pop(key, None)
    return env


def build_labels(project_name: str, component: str) -> Mapping[str, str]:
    """The labels of a build container (the same on this machine and on a host)."""
    return {naming.LABEL_PROJECT: project_name, naming.LABEL_COMPONENT: component, naming.LABEL_ROLE: "build"}


def record_host_build(project: Project, build: HostBuildPlan) -> None:
    """Write the state of a successful build on the host: where, of which image, the package hashes, and a
    new build id (sync's quick check of the host's install tree)."""
    write_build_state(project.host_build_state_file(build.component.name), {
        "host": build.host.name,
        "root": str(build.where.root),
        "image": build.image_id,
        "packages": build.packages,
        "build": os.urandom(8).hex(),
    })


def fetch_install(project: Project, comp: Component, host: Host, report: Reporter) -> None:
    """Bring the install tree that ``comp``'s host built back to this machine (for the dev shell), deltas only;
    when it cannot, one line says why and the shell goes on without it."""
    why = f"component {comp.name} is built on host {host.name} (builds_here: true)"
    state = read_build_state(project.host_build_state_file(comp.name))
    if state.get("host") != host.name:
        report.notice(f"{why} and was not built there yet: the shell has no install tree of it")
        return
    local = project.build_dir(comp.name) / "install"
    make_folder(local, shared=True)  # read by the dev shell, whose user may be another
    where = plan.host_build(host, comp.name)
    try:
        rsync.run(host, plan.fetch_install_argv(where, host, ssh.rsh_command(host), local), timeout=1800)
    except RobocoreError as exc:
        report.notice(f"{why}; its install tree could not be fetched ({exc.message}): the shell starts without it")
        return
    report.info(f"{comp.name}: install tree fetched from {host.name}, where it was built")
