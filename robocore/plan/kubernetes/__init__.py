"""``robocore export kubernetes``: a robot, or a fleet of robots, as kustomize for k3s, Rancher Fleet and Argo CD.

Pure planning: :func:`plan_export` turns the models (robot.yaml projects) and the robots of the fleet
into the files of the export folder, path -> text, the same bytes for the same input:

* ``bases/<model>/``: one kustomize base per model (:mod:`~robocore.plan.kubernetes.base`);
* ``robots/<robot>/``: one overlay per robot (:mod:`~robocore.plan.kubernetes.overlay`);
* ``kustomization.yaml``: every robot, for one cluster holding a node per robot host;
* ``fleet.yaml`` and ``argocd/applicationset.yaml``: the GitOps controllers, wave by wave
  (:mod:`~robocore.plan.kubernetes.gitops`).

What robot.yaml asks for that Kubernetes objects cannot say is refused first
(:mod:`~robocore.plan.kubernetes.refusals`); the pod settings are explained in
:mod:`~robocore.plan.kubernetes.pods`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from robocore.plan.kubernetes.base import KUSTOMIZATION, Base, kustomization, plan_base
from robocore.plan.kubernetes.gitops import APPLICATION_SET, FLEET_FILE, application_set, fleet_yaml
from robocore.plan.kubernetes.health import Gate
from robocore.plan.kubernetes.names import dump
from robocore.plan.kubernetes.overlay import ImageRef, ImageSource, RobotTarget, plan_overlay, robot_path
from robocore.plan.kubernetes.refusals import problems
from robocore.project import Project

__all__ = ["ExportOptions", "Gate", "ImageRef", "ImageSource", "RobotTarget", "plan_export", "problems"]


@dataclass(frozen=True)
class ExportOptions:
    """Where the GitOps controllers find the export: the git repository, the folder in it, the revision."""

    repository: str | None = None
    path: str = ""
    revision: str = "HEAD"


def release_key(base: Base, robots: Sequence[RobotTarget]) -> list[str]:
    """What the overlays of ``base``'s robots add to its pods: each robot's name, labels and domain, and the images
    it runs (the health Job's name hashes it; a Job's pods cannot change)."""
    key = []
    for robot in robots:
        if robot.model == base.model:
            images = ",".join(robot.images(repo, arch).text for repo, arch in base.images)
            key.append(f"{robot.name} {sorted(robot.labels.items())} {robot.ros_domain_id} {images}")
    return key


def plan_export(models: Mapping[str, Project], robots: Sequence[RobotTarget], project: str,
                options: ExportOptions = ExportOptions(), gates: Mapping[str, Gate] | None = None) -> dict[str, str]:
    """Every file of the export folder (path relative to it -> text). ``models``: model name -> its project
    (refusals already checked); ``robots`` in wave order; ``project``: the name the controllers' objects carry;
    ``gates``: each model's health gate (the defaults for a model without one)."""
    files: dict[str, str] = {}
    bases: dict[str, Base] = {}
    for model, source in sorted(models.items()):
        gate = (gates or {}).get(model, Gate())
        bases[model] = plan_base(source, model, gate, release_key(plan_base(source, model, gate), robots))
        files.update({f"bases/{model}/{name}": text for name, text in bases[model].files.items()})
    for robot in robots:
        ros2 = models[robot.model].robot.ros_version == 2
        overlay = plan_overlay(robot, bases[robot.model], ros2=ros2)
        files.update({f"{robot_path(robot.name)}/{name}": text for name, text in overlay.items()})
    files[KUSTOMIZATION] = dump([kustomization(resources=[robot_path(r.name) for r in robots])])
    files[FLEET_FILE] = fleet_yaml(robots, project, [(gates or {}).get(m, Gate()).deadline for m in bases])
    files[APPLICATION_SET] = application_set(robots, project, repository=options.repository, path=options.path,
                                             revision=options.revision)
    return dict(sorted(files.items()))
