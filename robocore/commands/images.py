"""prepare-base and stage: the images (issue #3); the colcon build is in :mod:`robocore.commands.build`.

- prepare-base: the base image (ROS + common packages), per arch of the hosts that need it;
- stage: one image per component (dependencies, no user code), in parallel, then compose files.

Images are rebuilt only when the content hash of their inputs (label ``dev.robocore.inputs``)
changes.
"""

from __future__ import annotations

import json
import os
import platform as host_platform
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager, suppress
from dataclasses import asdict, dataclass, field
from pathlib import Path, PurePosixPath
from typing import TYPE_CHECKING, Any

from robocore.commands.context import DRY_RUN_UNKNOWN, Options
from robocore.commands.workspace import (
    check_workspace,
    local_docker,
    selected_components,
    wheels_cmake_packages,
    workspace_files,
)
from robocore.config.loader import ROBOT_FILE
from robocore.config.model import BaseKind, Component, docker_arch
from robocore.errors import BuildError, ConfigError, DockerError, Problem, ToolMissing
from robocore.files import refuse_links_leaving
from robocore.plan import dockerfiles, naming
from robocore.plan.dockerfiles import ContextEntry, ImagePlan
from robocore.plan.inputs import inputs_hash
from robocore.project import Project

if TYPE_CHECKING:
    import docker

    from robocore.adapters.image_builder import ContextFile, ImageState

QEMU_NAME = {"arm64": "aarch64", "amd64": "x86_64"}
BINFMT_DIR = Path("/proc/sys/fs/binfmt_misc")
MAX_PARALLEL = 4


def native_arch() -> str:
    """The dev machine's arch in Docker terms."""
    return docker_arch(host_platform.machine())


def check_emulation(arch: str, native: str, who: str) -> None:
    """Raise ToolMissing when ``arch`` binaries cannot run here (no binfmt/qemu registration)."""
    if arch == native:
        return
    qemu = QEMU_NAME.get(arch, arch)
    if (BINFMT_DIR / f"qemu-{qemu}").exists():
        return
    raise ToolMissing(
        f"{who} needs {arch} images but this machine is {native} and cannot run {arch} binaries "
        f"({BINFMT_DIR}/qemu-{qemu} is missing)",
        hint=f"sudo apt-get install qemu-user-static binfmt-support (registers qemu-{qemu} with binfmt_misc), "
        f"or run `docker run --privileged --rm tonistiigi/binfmt --install {arch}`",
    )


def find_ca_bundle() -> Path | None:
    """The dev machine's trust store file (a public CA bundle plus any proxy CA), if any."""
    import ssl

    candidates = [os.environ.get(name) for name in ("REQUESTS_CA_BUNDLE", "PIP_CERT", "SSL_CERT_FILE")]
    paths = ssl.get_default_verify_paths()
    candidates += [paths.cafile, paths.openssl_cafile]
    for candidate in candidates:
        if candidate and Path(candidate).is_file():
            return Path(candidate)
    return None


# ---------------------------------------------------------------------------------------------- output


@dataclass
class Outcome:
    """What happened to one image or one colcon build."""

    what: str  # image reference or component name
    role: str  # base | component | build
    action: str  # built | up-to-date | would-build | unknown (dry run) | failed
    reason: str = ""
    image_id: str | None = None
    seconds: float = 0.0
    packages: list[str] = field(default_factory=list)


class Reporter:
    """Human progress on stderr (rich) unless quiet; a JSON result on stdout with --json."""

    def __init__(self, options: Options) -> None:
        self.options = options
        self.human = not options.quiet and not options.json

    def info(self, message: str, *, markup: bool = False) -> None:
        """A line of progress (rich markup only with ``markup``: the text may hold values from robot.yaml)."""
        if self.human:
            from robocore.ui import console

            console().print(message, markup=markup)

    def plain(self, text: str) -> None:
        """Plan text (dry run) on stdout, control characters escaped."""
        if not self.options.json:
            from robocore.ui import clean

            print(clean(text), flush=True)

    @contextmanager
    def progress(self) -> Iterator[Callable[[str, str], None]]:
        """``update(key, text)`` shows one live line per key while the block runs."""
        if not self.human:
            yield lambda key, text: None
            return
        from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

        from robocore.ui import console

        if not console().is_terminal:  # logs of CI: the build steps as plain lines

            def plain(key: str, text: str) -> None:
                if text.startswith(("Step ", "building")):
                    console().print(f"{key}: {text}", markup=False, highlight=False, soft_wrap=True)

            yield plain
            return
        tasks: dict[str, Any] = {}
        with Progress(SpinnerColumn(), TextColumn("{task.description}"), TimeElapsedColumn(),
                      console=console(), transient=True) as bar:

            def update(key: str, text: str) -> None:
                from robocore.ui import clean

                line = f"[bold]{key}[/]: {_escape(clean(text))[:100]}"
                if key not in tasks:
                    tasks[key] = bar.add_task(line, total=None)
                else:
                    bar.update(tasks[key], description=line)

            yield update

    def done(self, outcomes: Sequence[Outcome]) -> None:
        """Summary lines, or the JSON document."""
        if self.options.json:
            print(json.dumps({"results": [asdict(o) for o in outcomes]}, indent=2))
            return
        if not self.human:
            return
        for o in outcomes:
            mark = {"built": "[green]built[/]", "up-to-date": "[dim]up to date[/]",
                    "would-build": "[yellow]would build[/]", "unknown": "[yellow]build or keep[/]",
                    "failed": "[red]failed[/]"}.get(o.action, o.action)
            extra = f": {o.reason}" if o.action == "unknown" else f" ({o.reason})" if o.reason else ""
            secs = f" in {o.seconds:.1f}s" if o.action == "built" else ""
            self.info(f"{_escape(o.what)}: {mark}{secs}{_escape(extra)}", markup=True)


def _escape(text: str) -> str:
    from rich.markup import escape

    return escape(text)


# ---------------------------------------------------------------------------------------------- planning


def _config_problems(project: Project, found: list[tuple[tuple[str | int, ...], str]]) -> None:
    if found:
        raise ConfigError([Problem(ROBOT_FILE, None, ".".join(str(p) for p in path), message)
                           for path, message in found])


def _arches(project: Project, components: Sequence[Component] | None = None) -> list[str]:
    robot = project.robot
    comps = robot.components if components is None else components
    arches = sorted({robot.host(c.runs_on).arch.value for c in comps if c.image is None})
    return arches or [native_arch()]


def _cache(project: Project) -> Path:
    return project.state_dir / "cache"


def allowed_protocol(entry: object) -> str | None:
    """A repository or common package's ``allow_protocol`` opt-in (``file``, ``ext``, ...), if it has one."""
    value = getattr(entry, "allow_protocol", None)
    return value if isinstance(value, str) else None


def _fetch(project: Project, url: str, version: str | None, allow: str | None, *, refresh: bool,
           dry_run: bool) -> Path | None:
    """The checkout of ``url`` at ``version`` (fetched unless cached; ``allow`` is the entry's protocol
    opt-in); in a dry run the cached one, or None when there is none yet (nothing is fetched)."""
    from robocore.adapters import vcs

    dest = _cache(project) / "git" / vcs.cache_key(url, version)
    if dry_run:
        vcs.fetch_argv(url, version)  # the same checks as a fetch (a URL or version that is not one)
        return dest if (dest / ".git" / vcs.SOURCE_FILE).is_file() else None
    vcs.fetch(url, version, dest, refresh=refresh, allow_protocol=allow)
    return dest


def _resource(dest: str, name: str, *, executable: bool) -> ContextEntry:
    from robocore import resources

    return ContextEntry(dest=dest, data=resources.read(name), executable=executable)


@dataclass(frozen=True)
class Planned:
    """An image plan with its resolved context, inputs hash and decision."""

    plan: ImagePlan
    files: tuple[ContextFile, ...]
    parent_id: str
    inputs: str
    labels: dict[str, str]


def _planned(project: Project, plan: ImagePlan, parent_id: str, *, known: bool = True) -> Planned:
    """``plan`` with its context files and inputs hash; the hash is :data:`DRY_RUN_UNKNOWN` when the parent
    image or a source is unknown (a dry run)."""
    from robocore.adapters.image_builder import expand

    files = tuple(expand(plan.context))
    digest = inputs_hash(plan.dockerfile, [f.digest() for f in files], parent=parent_id, platform=plan.platform)
    if not known or parent_id == DRY_RUN_UNKNOWN:
        digest = DRY_RUN_UNKNOWN
    labels = {naming.LABEL_PROJECT: project.name, naming.LABEL_ROLE: plan.role, naming.LABEL_INPUTS: digest}
    if plan.component:
        labels[naming.LABEL_COMPONENT] = plan.component
    return Planned(plan=plan, files=files, parent_id=parent_id, inputs=digest, labels=labels)


def _base_parent(project: Project, client: docker.DockerClient | None, arch: str, *, dry_run: bool,
                 say: Callable[[str], None]) -> tuple[str, str]:
    """(FROM reference, its image ID) of the base for ``arch``; without a client (a dry run) the ID is
    :data:`DRY_RUN_UNKNOWN`."""
    from robocore.adapters import rootfs
    from robocore.adapters.image_builder import image_state

    robot = project.robot
    if client is None:
        default = rootfs.BOOTSTRAPPED if robot.base.kind is BaseKind.wheels else dockerfiles.official_image(robot)
        return robot.base.image or default, DRY_RUN_UNKNOWN
    if robot.base.kind is BaseKind.wheels:
        if dry_run:
            for ref in ([robot.base.image] if robot.base.image else [rootfs.BOOTSTRAPPED, rootfs.UPSTREAM]):
                state = image_state(client, ref)
                if state is not None:
                    return ref, state.id
            return robot.base.image or rootfs.BOOTSTRAPPED, "(to be bootstrapped)"
        return rootfs.ensure_root_image(client, robot.base.image, work_dir=_cache(project), status=say)
    ref = dockerfiles.official_image(robot)
    state = image_state(client, ref)
    if state is None and not dry_run:
        say(f"pulling {ref}")
        from docker.errors import DockerException

        with suppress(DockerException):
            client.images.pull(ref, platform=dockerfiles.platform(arch))
        state = image_state(client, ref)
    if state is None:
        if dry_run:
            return ref, "(to be pulled)"
        raise DockerError(
            f"robot.yaml: base image {ref} is not present locally and cannot be pulled",
            hint="pull or docker load it on this machine, or use base.kind: wheels (built from Debian and PyPI)",
        )
    return ref, state.id


def plan_base(project: Project, client: docker.DockerClient | None, arch: str, *, dry_run: bool = False,
              refresh_sources: bool = False, say: Callable[[str], None] = lambda _: None) -> Planned:
    """The base image plan for ``arch`` (resolves the root image and fetches common packages)."""
    robot = project.robot
    _config_problems(project, dockerfiles.wheels_problems(robot))
    native = native_arch()
    if not dry_run:
        check_emulation(arch, native, f"{ROBOT_FILE}: hosts of arch {arch}")
    root_ref, root_id = _base_parent(project, client, arch, dry_run=dry_run, say=say)
    ca = find_ca_bundle()
    entries: list[ContextEntry] = [_resource("entrypoint.sh", "entrypoint.sh", executable=True)]
    if robot.base.kind is BaseKind.wheels:
        from robocore import resources

        setup = resources.read("wheels-setup.bash").replace(b"@DISTRO@", robot.ros_distro.value.encode())
        entries += [ContextEntry("wheels-setup.bash", data=setup), _resource("ros2", "ros2", executable=True)]
    if ca is not None:
        entries.append(ContextEntry("host-ca.pem", data=ca.read_bytes()))
    common: list[str] = []
    known = True
    for pkg in robot.common_packages:
        if pkg.repo:
            source = _fetch(project, pkg.repo, pkg.branch, allowed_protocol(pkg), refresh=refresh_sources,
                            dry_run=dry_run)
        else:
            source = project.root / (pkg.folder or pkg.name)
            refuse_links_leaving(source, project.root, what=f"common package {pkg.name}, staged into the base image")
        if source is None:
            known = False  # a dry run before the first fetch
        else:
            entries.append(ContextEntry(f"common/{pkg.name}", source=source))
        common.append(pkg.name)
    cmake = wheels_cmake_packages(project, [e.source for e in entries if e.dest.startswith("common/") and e.source])
    dockerfile = dockerfiles.base_dockerfile(robot, root_image=root_ref, has_ca=ca is not None, common=common,
                                             cmake=cmake)
    plan = ImagePlan(role="base", name=naming.base_image(robot, project.name), tag=dockerfiles.base_tag(arch, native),
                     arch=arch, dockerfile=dockerfile, parent=root_ref, context=tuple(entries))
    return _planned(project, plan, root_id, known=known)


def package_xmls(ws: Path) -> list[str]:
    """Workspace-relative paths of every package.xml of a component's workspace."""
    return [rel for rel, _ in workspace_files(ws) if rel.rsplit("/", 1)[-1] == "package.xml"]


@dataclass(frozen=True)
class BaseRef:
    """A built base image as components see it: reference, arch and inputs hash."""

    ref: str
    arch: str
    inputs: str


def plan_component(project: Project, component: Component, base: BaseRef, *, dry_run: bool = False,
                   refresh_sources: bool = False) -> Planned:
    """The staged image plan of ``component`` on top of ``base``.

    Components hash on the base's inputs hash: an unchanged base leaves them unchanged.
    """
    robot = project.robot
    entries: list[ContextEntry] = []
    xmls: list[str] = []
    if robot.base.kind is BaseKind.official and component.folder:
        ws = check_workspace(project, component)
        for rel in package_xmls(ws):
            dest = dockerfiles.rosdep_dest(PurePosixPath(rel))
            entries.append(ContextEntry(dest, source=ws / rel))
            xmls.append(dest)
    folders: list[str] = []
    known = True
    for repo in component.repositories:
        folder = dockerfiles.repo_folder(repo)
        source = _fetch(project, repo.url, repo.version, allowed_protocol(repo), refresh=refresh_sources,
                        dry_run=dry_run)
        if source is None:
            known = False  # a dry run before the first fetch
        else:
            entries.append(ContextEntry(f"repos/{folder}", source=source))
        folders.append(folder)
    sources = [e.source for e in entries if e.dest.startswith("repos/") and e.source]
    if component.folder and robot.base.kind is BaseKind.wheels:
        sources.append(check_workspace(project, component))
    cmake = wheels_cmake_packages(project, sources)
    dockerfile = dockerfiles.component_dockerfile(robot, component, base_ref=base.ref, package_xmls=xmls,
                                                  repo_folders=folders, cmake=cmake)
    plan = ImagePlan(role="component", name=naming.component_image(robot, project.name, component.name),
                     tag="latest", arch=base.arch, dockerfile=dockerfile, parent=base.ref,
                     context=tuple(entries), component=component.name)
    return _planned(project, plan, base.inputs, known=known)


def decide(state: ImageState | None, planned: Planned, *, force: bool) -> str | None:
    """Why the image must be built, or None when it is up to date (:data:`DRY_RUN_UNKNOWN` when a dry run
    cannot know)."""
    if force:
        return "--force"
    if planned.inputs == DRY_RUN_UNKNOWN:
        return DRY_RUN_UNKNOWN
    if state is None:
        return "not built yet"
    if state.labels.get(naming.LABEL_INPUTS) != planned.inputs:
        return "inputs changed"
    return None


# ---------------------------------------------------------------------------------------------- execution


def _build_one(planned: Planned, reason: str, update: Callable[[str, str], None]) -> Outcome:
    from robocore.adapters.image_builder import build_image

    client = local_docker()
    start = time.monotonic()
    key = planned.plan.ref
    update(key, f"building ({reason})")
    try:
        image_id = build_image(client, planned.plan, planned.files, labels=planned.labels, native_arch=native_arch(),
                               output=lambda line: update(key, line))
    finally:
        client.close()
    return Outcome(what=key, role=planned.plan.role, action="built", reason=reason, image_id=image_id,
                   seconds=time.monotonic() - start)


def _show_plan(report: Reporter, planned: Planned, reason: str | None) -> None:
    if reason == DRY_RUN_UNKNOWN:
        status = f"build or keep: {DRY_RUN_UNKNOWN}"
    else:
        status = f"would build ({reason})" if reason else "up to date"
    inputs = planned.inputs if planned.inputs == DRY_RUN_UNKNOWN else planned.inputs[:19]
    report.plain(f"# {planned.plan.ref} [{planned.plan.platform}] inputs {inputs}: {status}")
    report.plain(planned.plan.dockerfile)


def _run_builds(report: Reporter, work: Sequence[tuple[Planned, str]], *, parallel: bool) -> list[Outcome]:
    outcomes: list[Outcome] = []
    if not work:
        return outcomes
    errors: list[BaseException] = []
    with report.progress() as update:
        if parallel and len(work) > 1:
            with ThreadPoolExecutor(max_workers=min(MAX_PARALLEL, len(work))) as pool:
                futures = [pool.submit(_build_one, planned, reason, update) for planned, reason in work]
                for future in futures:
                    try:
                        outcomes.append(future.result())
                    except BaseException as exc:  # collected: every image is tried, then one error
                        errors.append(exc)
        else:
            for planned, reason in work:
                outcomes.append(_build_one(planned, reason, update))
    if errors:
        report.done(outcomes)
        first = errors[0]
        if len(errors) > 1 and isinstance(first, BuildError):
            raise BuildError(first.message + f"\n(and {len(errors) - 1} more image(s) failed)", hint=first.hint)
        raise first
    return outcomes


def prepare_base(options: Options, *, force: bool) -> None:
    """Build the base image (per arch) when its inputs changed."""
    project = options.load()
    report = Reporter(options)
    _config_problems(project, dockerfiles.wheels_problems(project.robot))
    client = None if options.dry_run else local_docker()  # a dry run contacts no daemon
    from robocore.adapters.image_builder import image_state

    outcomes: list[Outcome] = []
    work: list[tuple[Planned, str]] = []
    for arch in _arches(project):
        planned = plan_base(project, client, arch, dry_run=options.dry_run, refresh_sources=force, say=report.info)
        reason = decide(image_state(client, planned.plan.ref) if client else None, planned, force=force)
        if options.dry_run:
            _show_plan(report, planned, reason)
        _triage(planned, reason, options.dry_run, outcomes, work)
    outcomes += _run_builds(report, work, parallel=False)
    report.done(outcomes)


def _triage(planned: Planned, reason: str | None, dry_run: bool,
            outcomes: list[Outcome], work: list[tuple[Planned, str]]) -> None:
    """Up to date, would build (dry run) or queued for building: the one decision per image."""
    if reason is None:
        outcomes.append(Outcome(what=planned.plan.ref, role=planned.plan.role, action="up-to-date"))
    elif reason == DRY_RUN_UNKNOWN:
        outcomes.append(Outcome(what=planned.plan.ref, role=planned.plan.role, action="unknown", reason=reason))
    elif dry_run:
        outcomes.append(Outcome(what=planned.plan.ref, role=planned.plan.role, action="would-build", reason=reason))
    else:
        work.append((planned, reason))


def _existing_base(project: Project, client: docker.DockerClient | None, arch: str, *,
                   dry_run: bool = False) -> BaseRef:
    """The built base image for ``arch`` (stage does not rebuild it: that is prepare-base's job); without
    a client (a dry run) its inputs are :data:`DRY_RUN_UNKNOWN`."""
    from robocore.adapters.image_builder import image_state

    ref = f"{naming.base_image(project.robot, project.name)}:{dockerfiles.base_tag(arch, native_arch())}"
    if client is None:
        return BaseRef(ref=ref, arch=arch, inputs=DRY_RUN_UNKNOWN)
    state = image_state(client, ref)
    if state is None or naming.LABEL_INPUTS not in state.labels:
        if dry_run:
            return BaseRef(ref=ref, arch=arch, inputs="(base not built yet: run prepare-base first)")
        raise BuildError(f"no base image {ref}", hint="run `prepare-base` first")
    return BaseRef(ref=ref, arch=arch, inputs=state.labels[naming.LABEL_INPUTS])


def _warn_stale_base(project: Project, client: docker.DockerClient, bases: dict[str, BaseRef],
                     report: Reporter) -> None:
    """Say so when robot.yaml or common packages changed since the base was built."""
    if any(pkg.repo for pkg in project.robot.common_packages):
        return  # git sources are only fetched by prepare-base
    for arch, base in bases.items():
        current = plan_base(project, client, arch, dry_run=True)
        if current.inputs != base.inputs and not base.inputs.startswith("("):
            report.info(f"[yellow]warning[/]: the inputs of {_escape(base.ref)} changed since it was built "
                        "(common packages or base settings); run prepare-base to rebuild it", markup=True)


def stage(options: Options, *, refresh: bool, component: str | None, force: bool) -> None:
    """Build component images (in parallel), then write the per-host compose files."""
    from robocore.commands.composefiles import write_compose_files

    project = options.load()
    report = Reporter(options)
    if refresh:
        if options.dry_run:
            report.plain("would rewrite the per-host compose files")
            return
        for path in write_compose_files(project):
            report.info(f"wrote {path.relative_to(project.root)}")
        return
    comps = selected_components(project, component)
    _config_problems(project, dockerfiles.wheels_problems(project.robot))
    client = None if options.dry_run else local_docker()  # a dry run contacts no daemon
    from robocore.adapters.image_builder import image_state

    bases = {arch: _existing_base(project, client, arch, dry_run=options.dry_run) for arch in _arches(project, comps)}
    if client is not None:
        _warn_stale_base(project, client, bases, report)
    outcomes: list[Outcome] = []
    work: list[tuple[Planned, str]] = []
    for comp in comps:
        base = bases[project.robot.host(comp.runs_on).arch.value]
        if not options.dry_run:
            check_emulation(base.arch, native_arch(), f"component {comp.name} (host {comp.runs_on})")
        planned = plan_component(project, comp, base, dry_run=options.dry_run, refresh_sources=force)
        reason = decide(image_state(client, planned.plan.ref) if client else None, planned, force=force)
        if options.dry_run:
            _show_plan(report, planned, reason)
            if comp.repositories:
                from robocore.adapters import vcs

                folders = {i: dockerfiles.repo_folder(r) for i, r in enumerate(comp.repositories)}
                report.plain(f"# {comp.name}: repositories (vcstool .repos), fetched on this machine into repos/\n"
                             + vcs.repos_file(comp.repositories, folders))
        _triage(planned, reason, options.dry_run, outcomes, work)
    if client is not None:
        client.close()
    outcomes += _run_builds(report, work, parallel=True)
    if options.dry_run:
        report.plain("then: rewrite the per-host compose files")
    else:
        for path in write_compose_files(project):
            report.info(f"wrote {path.relative_to(project.root)}")
    report.done(outcomes)
