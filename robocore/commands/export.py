"""export kubernetes: write the robot (or the fleet) as kustomize, Rancher Fleet and Argo CD files into a folder.

The plan is pure (:mod:`robocore.plan.kubernetes`); this module loads the projects, refuses what cannot
be exported (every problem, one line each, before anything is written), picks the release's images
and writes the folder with :func:`robocore.export_folder.write_tree`: a new or empty folder, or one a previous
export wrote, where only robocore's own files are replaced (its record is believed only as robocore's own records
are; see that module).

Each project is one model (its robot.yaml). Its robots are those of its fleet file, in their waves
(:func:`robocore.plan.fleet.plan_waves`); a project without a fleet file exports its one robot, named after
the project, in one wave. ``--model PATH`` adds other projects to the same export; waves of the same name
merge, in the order they first appear.

Images come from a release: when ``release --fleet --tag V`` recorded it (``.robocore/releases/V.json``), each
image by its digest for its host's arch (the self-contained fleet images: component image plus its install
tree); else the images ``robocore release --tag V`` pushed (``<registry>/<image>:V``, a multi-arch list; the
registry is the fleet file's, else robot.yaml's).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

from robocore.commands.support.context import Options
from robocore.config.loader import located, located_warnings
from robocore.errors import ConfigError, Problem, UsageError
from robocore.export_folder import check_folder, path_text, write_tree
from robocore.files import PRIVATE
from robocore.plan import naming
from robocore.plan.kubernetes import ExportOptions, Gate, ImageRef, ImageSource, RobotTarget, plan_export, problems
from robocore.plan.kubernetes.gitops import APPLICATION_SET, ETCD_REQUEST_LIMIT, FLEET_FILE, fleet_bundle_bytes
from robocore.plan.kubernetes.names import is_dns_label, k8s_name
from robocore.project import Project

if TYPE_CHECKING:
    from robocore.config.fleet import Fleet

#: The wave of a robot exported without a fleet file.
ONE_WAVE = "all"
#: What the export says of fleet.yaml's maintenance windows: Fleet and Argo CD have no counterpart in its files.
NO_SAFE_MOMENT = ("not in the Kubernetes export: Fleet and Argo CD update each robot when its partition or step "
                  "comes, whatever the time, and never ask the robot's update lock (/robocore/update_lock); only "
                  "`fleet rollout` on Swarm keeps the windows and the lock")


@dataclass(frozen=True)
class Exported:
    """What an export wrote: the folder, its files, the robots and the waves."""

    kind: ClassVar[str] = "export"
    folder: str
    files: list[str]
    robots: list[str]
    waves: list[str]


def model_name(project: Project) -> str:
    """The model's name in the export (its base folder and label): the project's name as a Kubernetes name."""
    name = k8s_name(project.name).replace(".", "-")
    if not is_dns_label(name):
        raise UsageError(f"project name {project.name!r} cannot be a Kubernetes name (letters, digits and '-', "
                         "at most 63, ending with a letter or digit)", hint="rename the project folder")
    return name


def tag_images(project: Project, tag: str, registry: str | None) -> ImageSource:
    """The images ``robocore release --tag TAG`` pushed: ``<registry>/<repository>:TAG``, one multi-arch name for
    every arch."""
    robot = project.robot.model_copy(update={"registry": registry}) if registry else project.robot

    def image(repository: str, arch: str) -> ImageRef:
        del arch  # the release's tag names a manifest list of every arch
        return ImageRef(name=naming.registry_image(robot, repository), tag=tag)

    return image


@dataclass(frozen=True)
class Model:
    """One model of the export: its name, its project, and its fleet file when it has one."""

    name: str
    project: Project
    fleet: Fleet | None


def has_fleet_release(project: Project, tag: str) -> bool:
    """Whether ``release --fleet --tag TAG`` recorded its images (``.robocore/releases/TAG.json`` exists): the
    pods then run self-contained images, which carry the read-only project volumes too."""
    import os

    from robocore.commands.fleet_release import record_path

    return os.path.lexists(record_path(project, tag))


def record_images(project: Project, tag: str, registry: str | None) -> ImageSource | None:
    """The images of the fleet release ``tag`` by digest (``release --fleet --tag V`` recorded them in
    ``.robocore/releases/V.json``: component image plus its install tree and read-only project volumes, per arch),
    None when that release has no record (the images are then named by tag). The record must name images of
    ``registry`` (the fleet's) only, each its own repository (:func:`load_release_record`)."""
    from robocore.commands.fleet_release import load_release_record

    if not has_fleet_release(project, tag):
        return None
    record = load_release_record(project, tag, registry)
    robot = project.robot
    base = naming.base_image(robot, project.name)
    components = {naming.component_image(robot, project.name, c.name): c.name for c in robot.components}

    def image(repository: str, arch: str) -> ImageRef:
        ref = record.base_ref(arch) if repository == base else record.component_ref(components[repository], arch)
        name, digest = ref.split("@", 1)
        return ImageRef(name=name, digest=digest)

    return image


def model_robots(model: Model, tag: str) -> list[RobotTarget]:
    """The robots of one model: its fleet file's, in wave order, or the project's one robot (no fleet file)."""
    robot = model.project.robot
    recorded = record_images(model.project, tag, model.fleet.registry_for(robot) if model.fleet else robot.registry)
    if model.fleet is None:
        return [RobotTarget(name=model.name, model=model.name, wave=ONE_WAVE,
                            images=recorded or tag_images(model.project, tag, robot.registry))]
    from robocore.plan.fleet import plan_waves

    fleet = model.fleet
    images = recorded or tag_images(model.project, tag, fleet.registry_for(robot))
    members = {member.name: member for member in fleet.robots}  # Fleet.robot scans: 10,000 robots, 10^8 steps
    targets = []
    for wave in plan_waves(fleet):
        for name in wave.robots:
            member = members[name]
            domain = member.ros_domain_id
            targets.append(RobotTarget(name=name, model=model.name, wave=wave.name, images=images,
                                       labels=dict(member.labels),
                                       ros_domain_id=domain if domain != robot.ros_domain_id else None))
    return targets


def bare_images(model: Model, tag: str) -> list[str]:
    """The components of ``model`` whose image would be a bare name (no registry, no fleet release record): what
    a node reads as a Docker Hub image, which no release pushed."""
    fleet = model.fleet
    registry = fleet.registry_for(model.project.robot) if fleet is not None else model.project.robot.registry
    if registry or has_fleet_release(model.project, tag):
        return []
    from robocore.plan.fleet_release import baked_volumes

    return [c.name for c in model.project.robot.components if not c.image or baked_volumes(c)]


def load_models(options: Options, others: list[Path], tag: str) -> list[Model]:
    """The models of the export (the task's project first), each with its fleet file; what any of them cannot
    export with release ``tag``'s images, and any problem of a fleet file, in one ConfigError."""
    projects = [options.load(), *(Project.load(path) for path in others)]
    found: list[Problem] = []
    models: dict[str, Model] = {}
    for project in projects:
        refused = problems(project.robot, fleet_images=has_fleet_release(project, tag))
        if refused:
            found += located(project.robot_file, refused).problems
        fleet = None
        if project.has_fleet:
            try:
                fleet = project.load_fleet()
            except ConfigError as error:
                found += error.problems
        name = model_name(project)
        if name in models:
            raise UsageError(f"{project.root} and {models[name].project.root} are both model {name!r}: the export "
                             "names each model after its project folder", hint="rename one project folder")
        models[name] = Model(name, project, fleet)
    if found:
        raise ConfigError(found)
    return list(models.values())


def merged(groups: list[list[RobotTarget]]) -> list[RobotTarget]:
    """Every robot of every model, waves of the same name merged in the order they first appear; a robot name
    given twice is a UsageError."""
    order: dict[str, int] = {}
    seen: dict[str, str] = {}
    for robots in groups:
        for robot in robots:
            order.setdefault(robot.wave, len(order))
            if robot.name in seen:
                raise UsageError(f"robot {robot.name!r} is in model {seen[robot.name]!r} and in model {robot.model!r}; "
                                 "a robot's name is its namespace, so it must be unique in an export")
            seen[robot.name] = robot.model
    flat = [robot for robots in groups for robot in robots]
    return sorted(flat, key=lambda r: order[r.wave])


def gitops_options(fleet: Fleet | None, git_repo: str | None, git_path: str | None) -> ExportOptions:
    """Where the controllers pull the export from: ``--git-repo``/``--git-path``, else the fleet file's ``gitops``
    (of the task's project); a bad option is a UsageError of one line."""
    from robocore.config.sources import gitops_url
    from robocore.config.values import git_folder

    for option, value, check in (("--git-repo", git_repo, gitops_url), ("--git-path", git_path, git_folder)):
        if value is not None:
            try:
                check(value)
            except ValueError as error:
                raise UsageError(f"{option}: {error}") from None
    given = fleet.gitops if fleet is not None else None
    repository = git_repo if git_repo is not None else (given.repo if given else None)
    path = git_path if git_path is not None else (given.path if given else "")
    return ExportOptions(repository=repository, path=path)


def export_kubernetes(options: Options, folder: Path, *, tag: str | None, git_repo: str | None = None,
                      git_path: str | None = None, models: list[Path] | None = None) -> Exported:
    """Export the project's robots (and those of ``models``) as kustomize and the GitOps controllers' files into
    ``folder``."""
    if tag is None:
        raise UsageError("export kubernetes needs --tag V: the release whose images the robots run",
                         hint="robocore release --tag v1, then robocore export kubernetes DIR --tag v1")
    loaded = load_models(options, list(models or []), tag)
    gitops = gitops_options(loaded[0].fleet, git_repo, git_path)
    robots = merged([model_robots(model, tag) for model in loaded])
    projects = {model.name: model.project for model in loaded}
    gates = {model.name: Gate.of(model.fleet) for model in loaded}
    files = plan_export(projects, robots, loaded[0].name, gitops, gates)
    result = Exported(folder=str(folder), files=sorted(files), robots=[r.name for r in robots],
                      waves=list(dict.fromkeys(r.wave for r in robots)))
    checked = check_folder(folder, files)  # a folder the export refuses is refused first, by a dry run too
    report = options.report
    for model in loaded:
        codeless = [c.name for c in model.project.robot.components if c.has_workspace]
        if codeless and not has_fleet_release(model.project, tag):
            report.warn(f"{model.name}: release {tag} has no fleet release record, so its images are named by tag: "
                        f"the code-less images of `release --tag`, without the install trees of {', '.join(codeless)}; "
                        f"run `release --fleet --tag {tag}` for self-contained images by digest")
        bare = bare_images(model, tag)
        if bare:
            report.warn(f"{model.name}: no registry (registry: in robot.yaml or fleet.yaml), so the images of the "
                        f"discovery servers and of {', '.join(bare)} are bare names ({model.name}-base:{tag}) that a "
                        "node pulls from Docker Hub, where no release pushed them: set a registry and release again, "
                        "or import the images on every node (k3s ctr images import) before applying")
    for model in loaded:
        if model.fleet is not None and model.fleet.rollout.windows:
            for warning in located_warnings(model.project.fleet_file, [(("rollout", "windows"), NO_SAFE_MOMENT)]):
                report.warn(warning.message, warning)
    if fleet_bundle_bytes(files) > ETCD_REQUEST_LIMIT:
        report.warn(f"{FLEET_FILE}: Rancher Fleet would hold these {len(robots)} robots in one Bundle object of more "
                    f"than {ETCD_REQUEST_LIMIT / 2**20:.1f} MiB, etcd's default limit of one object, and fail to store "
                    "it (etcdserver: request is too large): split the fleet (a fleet.yaml, export folder and GitRepo "
                    "path for each part), or use Argo CD's ApplicationSet (an Application per robot)")
    if gitops.repository is None:
        report.warn(f"{APPLICATION_SET} names no git repository (a placeholder that never syncs): give "
                    "--git-repo URL, or gitops: {repo: URL} in fleet.yaml")
    if options.dry_run:
        report.notice(f"would write {len(files)} files into {path_text(folder)} (robots: {', '.join(result.robots)})")
        for name in files:
            report.info(f"  {name}")
        report.add(result)
        return result
    write_tree(folder, files, mode=PRIVATE, checked=checked)
    report.notice(f"wrote {len(files)} files into {path_text(folder)}: {len(robots)} robot(s), waves "
                  f"{', '.join(result.waves)}; check with: kubectl kustomize {path_text(folder)}")
    report.add(result)
    return result
