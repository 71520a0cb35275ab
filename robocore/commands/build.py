"""build: colcon inside each component's staged image, incremental, with a copy fast path.

The workspace and the outputs (``.robocore/build/<c>/{build,install,log}``) are bind-mounted
into a throw-away container of the component's staged image, which runs as the invoking user.
A package is rebuilt only when its source hash differs from the last successful build's, which
is recorded in the component's build state (:mod:`robocore.commands.support.state`) together with the
source file list and the plain copies colcon made of them. When an edit only touches files that
colcon copies verbatim (Python modules of ament_python packages, launch and config files), the new
contents are written over those copies and colcon is not started at all
(:mod:`robocore.plan.install_patch`); ``--full`` always runs colcon.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from robocore.commands.support import host_build
from robocore.commands.support.colcon_output import colcon_listener
from robocore.commands.support.context import DRY_RUN_UNKNOWN, Options
from robocore.commands.support.hosts import in_parallel, lock_holder
from robocore.commands.support.machine import MAX_PARALLEL, check_emulation, local_docker, native_arch
from robocore.commands.support.reporting import Outcome, Reporter, report_outcomes
from robocore.commands.support.state import read_build_state, write_build_state
from robocore.commands.support.workspace import (
    check_workspace,
    selected_components,
    wheels_cmake_packages,
    workspace_files,
)
from robocore.config.model import Component
from robocore.errors import BuildError, UnsafePath, UsageError
from robocore.files import SHARED, check_no_links, make_folder, read_project_file, remove_tree, write_atomic
from robocore.plan import arches, cmake_packages, colcon, install_patch, naming
from robocore.plan.inputs import FileDigest, digest_bytes, tree_hash
from robocore.plan.remote_build import builds_on_host
from robocore.project import Project

#: Output folders searched for plain copies of source files (not log/).
COPY_FOLDERS = ("install", "build")

#: ``{package: {package-relative path: (digest, executable)}}``
WorkspaceFiles = dict[str, dict[str, tuple[str, bool]]]


def workspace_packages(ws: Path) -> tuple[dict[str, str], WorkspaceFiles]:
    """Every package of a workspace: ``({name: workspace-relative folder}, {name: its files})``."""
    files = list(workspace_files(ws))
    roots = sorted((rel.rsplit("/", 1)[0] if "/" in rel else "" for rel, _ in files
                    if rel.rsplit("/", 1)[-1] == "package.xml"), key=len, reverse=True)
    def manifest(root: str) -> str:  # a FIFO or a link out of the workspace: one line, never a blocked read
        return read_project_file(ws / root / "package.xml", ws, what="package.xml").decode("utf-8", errors="replace")

    names = {root: colcon.package_name(manifest(root)) or root or ws.name for root in roots}
    found: WorkspaceFiles = {names[root]: {} for root in roots}
    for rel, path in files:
        owner = next((r for r in roots if r == "" or rel.startswith(r + "/")), None)
        if owner is None:
            continue
        info = path.lstat()
        data = os.readlink(path).encode() if path.is_symlink() else path.read_bytes()
        inside = rel[len(owner) + 1:] if owner else rel
        found[names[owner]][inside] = (digest_bytes(data), bool(info.st_mode & 0o111))
    return {name: root for root, name in names.items()}, found


def package_hashes(ws: Path) -> dict[str, str]:
    """``{package name: content hash of its folder}`` for every package of a workspace."""
    return _hashes(*workspace_packages(ws))


def _hashes(roots: Mapping[str, str], files: WorkspaceFiles) -> dict[str, str]:
    return {name: tree_hash(FileDigest(f"{roots[name]}/{rel}" if roots[name] else rel, executable, digest)
                            for rel, (digest, executable) in members.items())
            for name, members in files.items()}


@dataclass(frozen=True)
class BuildPlan:
    """What ``build`` does for one component."""

    component: Component
    image: str
    image_id: str | None  # None: unknown (a dry run contacts no daemon)
    arch: str
    workspace: Path
    out: Path
    state_file: Path  # the build state, read to plan and written after a success
    packages: dict[str, str]
    files: WorkspaceFiles
    roots: dict[str, str]  # package -> workspace-relative folder
    changed: list[str] | None  # None: everything; []: nothing
    reason: str
    patches: tuple[install_patch.Patch, ...] = ()  # non-empty: copy files instead of running colcon
    copies: Mapping[str, Mapping[str, list[str]]] | None = None  # the last build's plain copies
    workers: int = 1  # packages and compile jobs at once: the cores
    ccache: Path | None = None  # the host folder of ccache's cache (per arch), when the image has ccache
    clean: bool = False  # the build and install trees hold another arch's objects: removed before colcon

    @property
    def argv(self) -> list[str]:
        """The colcon command line."""
        return colcon.workspace_build_argv(self.changed or (), self.workers)


def _recorded_files(before: Mapping[str, Any]) -> WorkspaceFiles:
    raw = before.get("files")
    if not isinstance(raw, dict):
        return {}
    out: WorkspaceFiles = {}
    for package, members in raw.items():
        if isinstance(members, dict):
            out[package] = {rel: (str(v[0]), bool(v[1])) for rel, v in members.items()
                            if isinstance(v, list) and len(v) == 2}
    return out


def plan_build(project: Project, comp: Component, image_id: str | None, *, full: bool = False) -> BuildPlan:
    """Which packages of ``comp`` must be (re)built, from the last successful build's state.

    Unless ``full``, an edit that only changes plain-copied files becomes a list of patches.
    ``image_id`` None (a dry run, which asks no daemon) takes the staged image as unchanged and says so.
    """
    ws = check_workspace(project, comp)
    out = project.build_dir(comp.name)
    arch = project.robot.host(comp.runs_on).arch.value
    roots, files = workspace_packages(ws)
    packages = _hashes(roots, files)
    state_file = project.build_state_file(comp.name)
    before = read_build_state(state_file)
    old: dict[str, str] = before.get("packages", {}) if isinstance(before.get("packages"), dict) else {}
    changed: list[str] | None
    patches: list[install_patch.Patch] = []
    copies = before.get("copies") if isinstance(before.get("copies"), dict) else None
    built_for = str(before.get("arch") or arch_of_install(out / "install") or arch)
    clean = built_for != arch and (out / "install").is_dir()
    if clean:
        changed, reason = None, f"arch changed ({built_for} -> {arch}): clean build"
    elif not (out / "install").is_dir() or (image_id is not None and before.get("image") != image_id):
        changed, reason = None, "first build" if not before else "image changed"
    elif set(old) != set(packages):
        changed, reason = None, "packages added or removed"
    else:
        changed = sorted(name for name, digest in packages.items() if old.get(name) != digest)
        reason = f"changed: {', '.join(changed)}" if changed else "up to date"
        if changed and not full and copies is not None:
            patches, why = install_patch.plan_patches(changed, _recorded_files(before), files, copies)
            if patches:
                reason += f" ({len(patches)} file{'s' if len(patches) != 1 else ''} copied, no colcon)"
            elif why:
                reason += f" (colcon: {why})"
    if image_id is None and before:
        reason += f"; whether the staged image changed: {DRY_RUN_UNKNOWN}"
    image = f"{naming.component_image(project.robot, project.name, comp.name)}:latest"
    return BuildPlan(component=comp, image=image, image_id=image_id, arch=arch,
                     workspace=ws, out=out, state_file=state_file, packages=packages,
                     files=files, roots=roots, changed=changed, reason=reason,
                     patches=tuple(patches), copies=copies, workers=os.cpu_count() or 1, clean=clean)


def with_cmake_toolchain(project: Project, plan: BuildPlan, labels: Mapping[str, str]) -> BuildPlan:
    """``plan`` building with ccache when its staged image (``labels``) has the CMake tool chain; a
    BuildError when the wheels base lacks the tool chain that packages of the workspace need."""
    if labels.get(cmake_packages.LABEL_TOOLCHAIN) == cmake_packages.TOOLCHAIN_CMAKE:
        return dataclasses.replace(plan, ccache=project.state_dir / arches.CCACHE_FOLDER / plan.arch)
    missing = wheels_cmake_packages(project, [plan.workspace])
    if missing:
        raise BuildError(f"component {plan.component.name}: {', '.join(missing)} build with CMake, but its image "
                         "was staged without the CMake tool chain", hint="run `stage` first")
    return plan


def _log_tail(out: Path, package: str, lines: int = 30) -> str:
    latest = out / "log" / "latest_build"
    for log in (latest / package / "stdout_stderr.log", latest / "logger_all.log"):
        try:
            text = log.read_text(errors="replace").splitlines()
        except OSError:
            continue
        return "\n".join(f"  {line}" for line in text[-lines:])
    return f"(no log under {latest})"


# ---------------------------------------------------------------------------------------------- colcon


def _colcon(project: Project, plan: BuildPlan, report: Reporter, update: Callable[[str, str], None]) -> Outcome:
    """colcon build of one component in a throw-away container of its staged image."""
    from robocore.adapters.image_builder import run_streaming

    if plan.clean:  # CMake would keep the other arch's objects (same compiler path, older sources)
        for sub in ("build", "install"):
            remove_tree(plan.out / sub)
    for sub in ("build", "install", "log"):  # mounted into the container: a link here would let colcon write elsewhere
        make_folder(plan.out / sub, shared=sub == "install")  # the install tree is sent to hosts and read there
    uid, gid = os.getuid(), os.getgid()
    if plan.ccache is not None:
        make_folder(plan.ccache)
    volumes = colcon.workspace_mounts(plan.workspace, plan.out, plan.ccache)
    events: list[colcon.PackageEvent] = []
    other: list[str] = []
    start = time.monotonic()
    name = plan.component.name
    native = native_arch()
    client = local_docker()
    try:
        update(name, "colcon build")

        on_line = colcon_listener(name, "building", "", events, other, update, report)
        attempts = [plan.argv] + ([colcon.workspace_build_argv((), plan.workers)] if plan.changed else [])
        for argv in attempts:
            code = run_streaming(
                client, plan.image, argv, user=f"{uid}:{gid}", volumes=volumes,
                environment=colcon.build_env(plan.workers, ccache=plan.ccache is not None),
                labels={naming.LABEL_PROJECT: project.name, naming.LABEL_COMPONENT: name,
                        naming.LABEL_ROLE: "build"},
                platform=arches.platform(plan.arch) if plan.arch != native else None, on_line=on_line,
            )
            # an image whose colcon lacks colcon-package-selection: build everything instead
            if not (code == 2 and any("--packages-above" in line for line in other[-3:])):
                break
            other.clear()
    finally:
        client.close()
    if code != 0:
        failed = [e.package for e in events if e.state == "failed"]
        if failed:
            raise BuildError(f"component {name}: colcon build failed in package {failed[0]} "
                             f"(log: {plan.out.relative_to(project.root)}/log/latest_build/{failed[0]})\n"
                             + _log_tail(plan.out, failed[0]),
                             hint=f"fix it in {plan.component.folder}, then run build --component {name}")
        tail = "\n".join(f"  {line}" for line in other[-20:])
        raise BuildError(f"component {name}: colcon build exited {code}\n{tail}")
    colcon.refuse_unbuilt(name, plan.packages, plan.changed, events, other)
    write_atomic(plan.out / "install" / arches.INSTALL_ARCH_FILE, plan.arch + "\n", mode=SHARED)  # sent with the tree
    record_build(plan)
    built = [e.package for e in events if e.state == "finished"]
    return Outcome(what=name, role="build", action="built", reason=plan.reason, image_id=plan.image_id,
                   seconds=time.monotonic() - start, packages=built)


def build(options: Options, *, component: str | None, full: bool = False) -> None:
    """colcon-build component workspaces inside their staged images (incremental; plain copies patched)."""
    project = options.load()
    report = options.report
    comps = [c for c in selected_components(project, component) if c.folder is not None]
    if component and not comps:
        raise UsageError(f"component {component!r} has no folder: nothing to build")
    from robocore.adapters.image_builder import image_state

    plans: list[BuildPlan] = []
    if options.dry_run:  # a dry run contacts no daemon: the staged images are not looked at
        plans = [plan_build(project, comp, None, full=full) for comp in comps]
    else:
        client = local_docker()
        try:
            for comp in comps:
                ref = f"{naming.component_image(project.robot, project.name, comp.name)}:latest"
                state = image_state(client, ref)
                if state is None:
                    raise BuildError(f"component {comp.name}: no staged image {ref}", hint="run `stage` first")
                if not builds_on_host(project.robot.host(comp.runs_on)):  # else built natively on its host
                    check_emulation(project.robot.host(comp.runs_on).arch.value, native_arch(),
                                    f"component {comp.name}")
                plans.append(with_cmake_toolchain(project, plan_build(project, comp, state.id, full=full),
                                                  state.labels))
        finally:
            client.close()
    outcomes: list[Outcome] = []
    todo: list[BuildPlan] = []
    on_hosts, plans = _host_plans(project, plans)
    for hplan in on_hosts:
        if hplan.changed == []:
            outcomes.append(Outcome(what=hplan.component.name, role="build", action="up-to-date", reason=hplan.reason))
        elif options.dry_run:
            report.plain(f"# {hplan.component.name} ({hplan.reason}):")
            steps = host_build.dry_run_steps(hplan, check_workspace(project, hplan.component))
            for step in steps:
                report.plain(f"  {step}")
            outcomes.append(Outcome(what=hplan.component.name, role="build", action="would-build",
                                    reason=hplan.reason, plan="\n".join(steps)))
    on_hosts = [h for h in on_hosts if h.changed != []] if not options.dry_run else []
    for plan in plans:
        if plan.changed == []:
            outcomes.append(Outcome(what=plan.component.name, role="build", action="up-to-date"))
            continue
        if options.dry_run:
            if plan.patches:
                report.plain(f"# {plan.component.name} ({plan.reason}):")
                steps = [f"copy {patch.package}/{patch.source} -> " + ", ".join(patch.targets)
                         for patch in plan.patches]
            else:
                report.plain(f"# {plan.component.name} ({plan.reason}) in {plan.image}:")
                steps = [" ".join(plan.argv)]
            for step in steps:
                report.plain(f"  {step}")
            outcomes.append(Outcome(what=plan.component.name, role="build", action="would-build", reason=plan.reason,
                                    plan="\n".join(steps)))
            continue
        if plan.patches:
            patched = apply_patches(plan)
            if patched is not None:
                outcomes.append(patched)
                continue
            plan = dataclasses.replace(plan, patches=(), reason=f"changed: {', '.join(plan.changed or [])} "
                                       "(colcon: an output differs from what the last build wrote)")
        todo.append(plan)
    outcomes += _run_colcon(project, todo, on_hosts, report)
    report_outcomes(report, outcomes)


def _host_plans(project: Project, plans: Sequence[BuildPlan]) -> tuple[list[host_build.HostBuildPlan],
                                                                         list[BuildPlan]]:
    """``plans`` split into the builds on the components' own hosts (``builds_here``) and those on this machine."""
    on_hosts: list[host_build.HostBuildPlan] = []
    here: list[BuildPlan] = []
    for plan in plans:
        host = project.robot.host(plan.component.runs_on)
        if builds_on_host(host):
            on_hosts.append(host_build.plan_host_build(project, plan.component, host, plan.image, plan.image_id,
                                                       plan.packages, ccache=plan.ccache is not None))
        else:
            here.append(plan)
    return on_hosts, here


def _run_colcon(project: Project, todo: Sequence[BuildPlan], on_hosts: Sequence[host_build.HostBuildPlan],
                report: Reporter) -> list[Outcome]:
    """colcon builds of several components side by side (one container each, here or on their hosts); every
    one is tried."""
    if not todo and not on_hosts:
        return []
    holder = lock_holder()
    with report.progress() as update:
        jobs: list[Callable[[], Outcome]] = [functools.partial(_colcon, project, plan, report, update)
                                             for plan in todo]
        jobs += [functools.partial(host_build.build_on_host, project, hplan,
                                   check_workspace(project, hplan.component), holder, report, update)
                 for hplan in on_hosts]
        done = in_parallel(jobs, lambda job: job(), limit=MAX_PARALLEL, name="robocore-colcon")
    outcomes = [result for _, result in done if not isinstance(result, BaseException)]
    errors = [result for _, result in done if isinstance(result, BaseException)]
    if errors:
        report_outcomes(report, outcomes)
        raise errors[0]
    return outcomes


# ---------------------------------------------------------------------------------------------- state


def arch_of_install(install: Path) -> str | None:
    """The arch an install tree records (:data:`robocore.plan.arches.INSTALL_ARCH_FILE`), None when it records none."""
    try:
        text = (install / arches.INSTALL_ARCH_FILE).read_text().strip()
    except OSError:
        return None
    return text or None


def output_candidates(out: Path, files: WorkspaceFiles) -> dict[str, str]:
    """Digests of the regular files under ``out``/{install,build} named like some source file."""
    names = {rel.rsplit("/", 1)[-1] for members in files.values() for rel in members}
    found: dict[str, str] = {}
    for folder in COPY_FOLDERS:
        for dirpath, _, filenames in os.walk(out / folder):
            for name in filenames:
                if name not in names:
                    continue
                path = Path(dirpath) / name
                if path.is_symlink() or not path.is_file():
                    continue
                found[path.relative_to(out).as_posix()] = digest_bytes(path.read_bytes())
    return found


def record_build(plan: BuildPlan) -> None:
    """Write the build state after a successful colcon run: package hashes, files and their copies."""
    outputs = output_candidates(plan.out, plan.files)
    copies = {package: install_patch.verbatim_copies(package, members, outputs)
              for package, members in plan.files.items()}
    _record(plan, copies)


def _record(plan: BuildPlan, copies: Mapping[str, Mapping[str, list[str]]]) -> None:
    write_build_state(plan.state_file, {
        "arch": plan.arch,
        "image": plan.image_id,
        "packages": plan.packages,
        "files": {p: {rel: [d, x] for rel, (d, x) in sorted(m.items())} for p, m in sorted(plan.files.items())},
        "copies": copies,
    })


# ---------------------------------------------------------------------------------------------- fast path


def apply_patches(plan: BuildPlan) -> Outcome | None:
    """Write each patched source over its recorded copies; None (nothing written) if any copy was changed
    or a source was edited again since planning.

    Every target and every source is checked first (a target must be a regular file still holding the
    recorded content), then each target is replaced atomically with the new content, keeping its mode.
    """
    start = time.monotonic()
    for patch in plan.patches:
        for target in patch.targets:
            path = plan.out / target
            try:
                check_no_links(path)  # a target behind a link (colcon's --symlink-install): colcon does it
            except UnsafePath:
                return None
            if not path.is_file() or digest_bytes(path.read_bytes()) != patch.old_digest:
                return None
    contents = [_source_path(plan, patch).read_bytes() for patch in plan.patches]
    if any(digest_bytes(data) != patch.digest for patch, data in zip(plan.patches, contents, strict=True)):
        return None  # edited again since planning: let colcon do it
    for patch, data in zip(plan.patches, contents, strict=True):
        for target in patch.targets:
            path = plan.out / target
            write_atomic(path, data, mode=path.stat().st_mode & 0o7777)
    assert plan.copies is not None
    _record(plan, plan.copies)
    return Outcome(what=plan.component.name, role="build", action="built", reason=plan.reason,
                   image_id=plan.image_id, seconds=time.monotonic() - start,
                   packages=sorted({p.package for p in plan.patches}))


def _source_path(plan: BuildPlan, patch: install_patch.Patch) -> Path:
    root = plan.roots[patch.package]
    return plan.workspace / root / patch.source if root else plan.workspace / patch.source

