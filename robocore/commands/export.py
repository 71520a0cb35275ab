"""export kubernetes: write the robot (or the fleet) as kustomize, Rancher Fleet and Argo CD files into a folder.

The plan is pure (:mod:`robocore.plan.kubernetes`); this module loads the project, refuses what cannot
be exported (every problem, one line each, before anything is written), picks the release's images
and writes the folder with :func:`robocore.files.write_tree`: a new or empty folder, or one a previous
export wrote, where only robocore's own files are replaced.

Images come from a release: ``--tag V`` names the images ``robocore release --tag V`` pushed
(``<registry>/<image>:V``, a multi-arch list). Without a fleet file the project's one robot is exported,
named after the project, in one wave.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from robocore.commands.context import Options
from robocore.config.loader import located
from robocore.errors import UsageError
from robocore.files import PRIVATE, write_tree
from robocore.plan import naming
from robocore.plan.kubernetes import ExportOptions, ImageRef, ImageSource, RobotTarget, plan_export, problems
from robocore.plan.kubernetes.names import is_dns_label, k8s_name
from robocore.project import Project

#: The wave of a robot exported without a fleet file.
ONE_WAVE = "all"


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


def refuse(project: Project) -> None:
    """Raise one ConfigError naming every key of robot.yaml the export cannot express."""
    found = problems(project.robot)
    if found:
        raise located(project.robot_file, found)


def export_kubernetes(options: Options, folder: Path, *, tag: str | None, git_repo: str | None = None,
                      git_path: str = "") -> Exported:
    """Export the project's robot as kustomize and the GitOps controllers' files into ``folder``."""
    if tag is None:
        raise UsageError("export kubernetes needs --tag V: the release whose images the robots run",
                         hint="robocore release --tag v1, then robocore export kubernetes DIR --tag v1")
    project = options.load()
    refuse(project)
    model = model_name(project)
    robots = [RobotTarget(name=model, model=model, wave=ONE_WAVE,
                          images=tag_images(project, tag, project.robot.registry))]
    files = plan_export({model: project}, robots, model, ExportOptions(repository=git_repo, path=git_path))
    result = Exported(folder=str(folder), files=sorted(files), robots=[r.name for r in robots],
                      waves=list(dict.fromkeys(r.wave for r in robots)))
    report = options.report
    if options.dry_run:
        report.notice(f"would write {len(files)} files into {folder} (robots: {', '.join(result.robots)})")
        for name in files:
            report.info(f"  {name}")
        report.add(result)
        return result
    write_tree(folder, files, mode=PRIVATE)
    report.notice(f"wrote {len(files)} files into {folder}: {len(robots)} robot(s), waves "
                  f"{', '.join(result.waves)}; check with: kubectl kustomize {folder}")
    report.add(result)
    return result

