"""prepare-base: the base image (ROS plus ``common_packages``), one per arch of the hosts that need it.

The base is rebuilt only when its inputs hash changes. Its parent is the official ROS image
(pulled when missing) or, for the wheels and debian bases, a Debian root image robocore bootstraps itself.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from robocore.commands.support.context import DRY_RUN_UNKNOWN, Options
from robocore.commands.support.images import (
    Planned,
    allowed_protocol,
    base_arches,
    decide,
    fetch_source,
    planned,
    resource_entry,
    run_builds,
    show_plan,
    triage,
)
from robocore.commands.support.machine import check_emulation, find_ca_bundle, local_docker, native_arch
from robocore.commands.support.reporting import Outcome, report_outcomes
from robocore.commands.support.workspace import wheels_cmake_packages
from robocore.config.model import BaseKind
from robocore.files import ROBOT_FILE, refuse_links_leaving
from robocore.plan import arches, dockerfiles, naming, wheels_venv
from robocore.plan.dockerfiles import ContextEntry, ImagePlan
from robocore.project import Project

if TYPE_CHECKING:
    import docker

#: Base kinds built on a Debian root image that robocore bootstraps (no image registry needed).
ROOTFS_KINDS = frozenset({BaseKind.wheels, BaseKind.debian})


def root_strap(project: Project, arch: str) -> arches.RootStrap | None:
    """How the base's root is bootstrapped for ``arch`` (None: the official base and ``base.image`` are pulled).
    The wheels base's root gets the base's venv and settings too, the venv installed where writes are cheap (see
    :mod:`robocore.plan.wheels_venv`): on fuse-overlayfs that venv, and each build step on top of it, was most of
    a first ``prepare-base``."""
    robot = project.robot
    if robot.base.kind not in ROOTFS_KINDS or robot.base.image:
        return None
    if robot.base.kind is BaseKind.debian:
        return arches.root_strap(robot.base.kind, arch, dockerfiles.DEBIAN_APT)
    from robocore.adapters.image_builder import PROXY_VARS

    distro = robot.ros_distro.value
    env = dockerfiles.venv(distro)
    ca = find_ca_bundle()
    hook = wheels_venv.root_hook(env, dockerfiles.wheels_pins(distro), ca=None if ca is None else str(ca),
                                 passed=PROXY_VARS)
    return arches.root_strap(robot.base.kind, arch, dockerfiles.WHEELS_APT, venv=env, venv_hook=hook,
                             config=dockerfiles.wheels_root_config(distro, has_ca=ca is not None))


def _base_parent(project: Project, client: docker.DockerClient | None, arch: str, *, dry_run: bool,
                 say: Callable[[str], None], strap: arches.RootStrap | None) -> tuple[str, str]:
    """(FROM reference, its image ID) of the base for ``arch``: always the per-arch local name of its root
    (:func:`robocore.plan.arches.base_root`), bootstrapped from ``strap`` (its :func:`root_strap`) when it is to
    be made; without a client (a dry run) the ID is :data:`DRY_RUN_UNKNOWN`."""
    from robocore.adapters import rootfs
    from robocore.adapters.image_builder import image_state

    robot = project.robot
    target = arches.base_root(robot, arch)
    if client is None:
        return target, DRY_RUN_UNKNOWN
    if dry_run:
        state = image_state(client, target)
        if state is not None and state.arch == arch:
            return target, state.id
        return target, "(to be bootstrapped)" if strap is not None else "(to be pulled)"
    return rootfs.ensure_root_image(client, target=target, upstream=arches.upstream_root(robot), arch=arch,
                                    strap=strap, work_dir=project.cache_dir / "rootfs", status=say)


def plan_base(project: Project, client: docker.DockerClient | None, arch: str, *, dry_run: bool = False,
              refresh_sources: bool = False, say: Callable[[str], None] = lambda _: None) -> Planned:
    """The base image plan for ``arch`` (resolves the root image and fetches common packages). Whether this
    machine can run ``arch`` is :func:`prepare_base`'s check, made for every arch before any root is made."""
    robot = project.robot
    dockerfiles.refuse_robot_shape(project)
    native = native_arch()
    strap = root_strap(project, arch)
    root_ref, root_id = _base_parent(project, client, arch, dry_run=dry_run, say=say, strap=strap)
    ca = find_ca_bundle()
    wheels = robot.base.kind is BaseKind.wheels
    tree = robot.base.kind in dockerfiles.TREE_KINDS

    def place(name: str) -> str:  # the wheels and debian bases copy their files in one step, from a tree
        return dockerfiles.base_tree_dest(name, robot.ros_distro.value) if tree else name

    entries: list[ContextEntry] = [resource_entry(place("entrypoint.sh"), "entrypoint.sh", executable=True),
                                   resource_entry(place("setup-python"), "setup-python", executable=True)]
    if wheels:
        from robocore import resources

        setup = resources.read("wheels-setup.bash").replace(b"@DISTRO@", robot.ros_distro.value.encode())
        entries += [ContextEntry(place("wheels-setup.bash"), data=setup),
                    resource_entry(place("ros2"), "ros2", executable=True)]
    elif robot.base.kind is BaseKind.debian:
        entries.append(resource_entry(place("debian-setup.bash"), "debian-setup.bash", executable=False))
    if ca is not None:
        entries.append(ContextEntry(place("host-ca.pem"), data=ca.read_bytes()))
    common: list[str] = []
    known = True
    for pkg in robot.common_packages:
        if pkg.repo:
            source = fetch_source(project, pkg.repo, pkg.branch, allowed_protocol(pkg), refresh=refresh_sources,
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
                                             cmake=cmake, venv_in_root=_venv_in_root(client, strap, root_ref))
    plan = ImagePlan(role="base", name=naming.base_image(robot, project.name), tag=arches.base_tag(arch, native),
                     arch=arch, dockerfile=dockerfile, parent=root_ref, context=tuple(entries),
                     labels=dockerfiles.base_labels(robot))
    return planned(project, plan, root_id, known=known)


def _venv_in_root(client: docker.DockerClient | None, strap: arches.RootStrap | None, root_ref: str) -> bool:
    """Whether the root image ``root_ref`` holds the wheels base's venv: it is the root robocore bootstrapped from
    ``strap``, the project's :func:`root_strap` (a pulled root, or none yet in a dry run, has no venv: the base
    installs it)."""
    if client is None or strap is None or not strap.venv:
        return False
    from robocore.adapters import rootfs
    from robocore.adapters.image_builder import image_state

    return rootfs.made_from(image_state(client, root_ref), strap)


def prepare_base(options: Options, *, force: bool) -> None:
    """Build the base image (per arch) when its inputs changed.

    The roots of all arches are made side by side, and each arch's base is built as soon as its root is there:
    an emulated bootstrap keeps one core busy for minutes, during which the native root and base are made on the
    other (a mixed robot from nothing is ready when the emulated arch is, not after both one by one)."""
    project = options.load()
    report = options.report
    dockerfiles.refuse_robot_shape(project)
    if options.dry_run:
        _show_bases(project, options, force=force)
        return
    from robocore.adapters.image_builder import image_state

    wanted = base_arches(project)
    native = native_arch()
    for arch in wanted:  # before any bootstrap starts
        check_emulation(arch, native, f"{ROBOT_FILE}: hosts of arch {arch}")
    client = local_docker()

    def build_base(arch: str) -> list[Outcome]:
        base = plan_base(project, client, arch, refresh_sources=force, say=report.info)
        outcomes: list[Outcome] = []
        work: list[tuple[Planned, str]] = []
        triage(base, decide(image_state(client, base.plan.ref), base, force=force), False, outcomes, work)
        return outcomes + run_builds(report, work, parallel=False)

    try:
        outcomes = bases_as_roots_arrive(wanted, lambda arch: _make_root(project, arch, report.info), build_base)
    finally:
        client.close()
    report_outcomes(report, outcomes)


def bases_as_roots_arrive(wanted: Sequence[str], make_root: Callable[[str], None],
                          build_base: Callable[[str], list[Outcome]]) -> list[Outcome]:
    """Make the root of every arch in ``wanted`` side by side (a thread each) and build each arch's base, in this
    thread, as soon as its root is there: the outcomes of the bases. A root that cannot be had raises its error
    once the roots still being made have finished; the bases of the roots that came before it are built."""
    from concurrent.futures import ThreadPoolExecutor, as_completed

    outcomes: list[Outcome] = []
    with ThreadPoolExecutor(max_workers=len(wanted), thread_name_prefix="robocore-root") as pool:
        roots = {pool.submit(make_root, arch): arch for arch in wanted}
        for done in as_completed(roots):
            done.result()  # the root's error, if it could not be had
            outcomes += build_base(roots[done])
    return outcomes


def _make_root(project: Project, arch: str, say: Callable[[str], None]) -> None:
    """Have ``arch``'s root image (kept, pulled or bootstrapped), with a Docker client of this thread's own."""
    client = local_docker()
    try:
        _base_parent(project, client, arch, dry_run=False, say=say, strap=root_strap(project, arch))
    finally:
        client.close()


def _show_bases(project: Project, options: Options, *, force: bool) -> None:
    """A dry run's plans: no daemon is contacted, nothing is pulled, bootstrapped or built."""
    outcomes: list[Outcome] = []
    work: list[tuple[Planned, str]] = []
    for arch in base_arches(project):
        base = plan_base(project, None, arch, dry_run=True, refresh_sources=force, say=options.report.info)
        reason = decide(None, base, force=force)
        show_plan(options.report, base, reason)
        triage(base, reason, True, outcomes, work)
    report_outcomes(options.report, outcomes)
