"""prepare-base: the base image (ROS plus ``common_packages``), one per arch of the hosts that need it.

The base is rebuilt only when its inputs hash changes. Its parent is the official ROS image
(pulled when missing) or, for the wheels and debian bases, a Debian root image robocore bootstraps itself.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from robocore.commands.context import DRY_RUN_UNKNOWN, Options
from robocore.commands.images import (
    Planned,
    allowed_protocol,
    arches,
    decide,
    fetch_source,
    planned,
    refuse_config_problems,
    resource_entry,
    run_builds,
    show_plan,
    triage,
)
from robocore.commands.machine import check_emulation, find_ca_bundle, local_docker, native_arch
from robocore.commands.reporting import Outcome, report_outcomes
from robocore.commands.workspace import wheels_cmake_packages
from robocore.config.model import BaseKind
from robocore.files import ROBOT_FILE, refuse_links_leaving
from robocore.plan import arches as per_arch
from robocore.plan import dockerfiles, naming
from robocore.plan.dockerfiles import ContextEntry, ImagePlan
from robocore.project import Project

if TYPE_CHECKING:
    import docker

#: Base kinds built on a Debian root image that robocore bootstraps (no image registry needed).
ROOTFS_KINDS = frozenset({BaseKind.wheels, BaseKind.debian})


def root_strap(project: Project, arch: str) -> per_arch.RootStrap | None:
    """How the base's root is bootstrapped for ``arch`` (None: the official base and ``base.image`` are pulled)."""
    robot = project.robot
    if robot.base.kind not in ROOTFS_KINDS or robot.base.image:
        return None
    packages = dockerfiles.DEBIAN_APT if robot.base.kind is BaseKind.debian else dockerfiles.WHEELS_APT
    return per_arch.root_strap(robot.base.kind, arch, packages)


def _base_parent(project: Project, client: docker.DockerClient | None, arch: str, *, dry_run: bool,
                 say: Callable[[str], None]) -> tuple[str, str]:
    """(FROM reference, its image ID) of the base for ``arch``: always the per-arch local name of its root
    (:func:`robocore.plan.arches.base_root`); without a client (a dry run) the ID is :data:`DRY_RUN_UNKNOWN`."""
    from robocore.adapters import rootfs
    from robocore.adapters.image_builder import image_state

    robot = project.robot
    target = per_arch.base_root(robot, arch)
    if client is None:
        return target, DRY_RUN_UNKNOWN
    if dry_run:
        state = image_state(client, target)
        if state is not None and state.arch == arch:
            return target, state.id
        strap = root_strap(project, arch)
        return target, "(to be bootstrapped)" if strap is not None else "(to be pulled)"
    return rootfs.ensure_root_image(client, target=target, upstream=per_arch.upstream_root(robot), arch=arch,
                                    strap=root_strap(project, arch), work_dir=project.cache_dir / "rootfs",
                                    status=say)


def plan_base(project: Project, client: docker.DockerClient | None, arch: str, *, dry_run: bool = False,
              refresh_sources: bool = False, say: Callable[[str], None] = lambda _: None) -> Planned:
    """The base image plan for ``arch`` (resolves the root image and fetches common packages)."""
    robot = project.robot
    refuse_config_problems(project)
    native = native_arch()
    if not dry_run:
        check_emulation(arch, native, f"{ROBOT_FILE}: hosts of arch {arch}")
    root_ref, root_id = _base_parent(project, client, arch, dry_run=dry_run, say=say)
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
                                             cmake=cmake)
    plan = ImagePlan(role="base", name=naming.base_image(robot, project.name), tag=dockerfiles.base_tag(arch, native),
                     arch=arch, dockerfile=dockerfile, parent=root_ref, context=tuple(entries))
    return planned(project, plan, root_id, known=known)


def prepare_base(options: Options, *, force: bool) -> None:
    """Build the base image (per arch) when its inputs changed."""
    project = options.load()
    report = options.report
    refuse_config_problems(project)
    client = None if options.dry_run else local_docker()  # a dry run contacts no daemon
    from robocore.adapters.image_builder import image_state

    outcomes: list[Outcome] = []
    work: list[tuple[Planned, str]] = []
    try:
        for arch in arches(project):
            base = plan_base(project, client, arch, dry_run=options.dry_run, refresh_sources=force, say=report.info)
            reason = decide(image_state(client, base.plan.ref) if client else None, base, force=force)
            if options.dry_run:
                show_plan(report, base, reason)
            triage(base, reason, options.dry_run, outcomes, work)
    finally:
        if client is not None:
            client.close()
    outcomes += run_builds(report, work, parallel=False)
    report_outcomes(report, outcomes)
