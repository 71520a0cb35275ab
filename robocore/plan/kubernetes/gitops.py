"""The GitOps controllers' files: a Rancher Fleet ``fleet.yaml`` and an Argo CD ApplicationSet, from the waves (pure).

Both take the export folder from a git repository and give each robot its overlay, one cluster per
robot (a k3s cluster on the robot, the shape Google's Cloud Robotics Core chose), wave after wave:

* **Rancher Fleet** (``fleet.yaml`` at the top of the folder, a bundle of kustomize): a cluster labelled
  ``robocore.dev/robot=<robot>`` gets ``robots/<robot>`` (``targetCustomizations``); any other cluster
  gets nothing (``doNotDeploy``), never the root kustomization of every robot. Each wave is a
  ``rolloutStrategy.partitions`` entry selecting its robots; ``maxUnavailablePartitions: 0`` and each
  partition's ``maxUnavailable: 0`` make Fleet finish a wave (every robot of it ready) before the next.
* **Argo CD** (``argocd/applicationset.yaml``): one Application per robot from a list generator,
  labelled with its wave; the ``RollingSync`` strategy syncs the waves' steps in order, each step
  waiting for its Applications to be healthy. Applications are not auto-synced (RollingSync drives them).
  The cluster of a robot is the Argo CD cluster named after it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from robocore.plan.kubernetes.names import LABEL_ROBOT, LABEL_WAVE, dump, namespace
from robocore.plan.kubernetes.overlay import RobotTarget, robot_path

#: The repository URL written when none is given: a reserved name that never resolves, so nothing syncs by mistake.
NO_REPOSITORY = "https://git.example.invalid/set-with--git-repo.git"
FLEET_FILE = "fleet.yaml"
APPLICATION_SET = "argocd/applicationset.yaml"


def waves_in_order(robots: Sequence[RobotTarget]) -> list[tuple[str, list[str]]]:
    """(wave, robot names) in the order the waves first appear."""
    waves: dict[str, list[str]] = {}
    for robot in robots:
        waves.setdefault(robot.wave, []).append(robot.name)
    return list(waves.items())


def _in(names: Sequence[str]) -> dict[str, Any]:
    return {"matchExpressions": [{"key": LABEL_ROBOT, "operator": "In", "values": list(names)}]}


def fleet_yaml(robots: Sequence[RobotTarget], project: str) -> str:
    """Rancher Fleet's ``fleet.yaml`` for the export folder."""
    customizations: list[dict[str, Any]] = [
        {"name": robot.name, "clusterSelector": {"matchLabels": {LABEL_ROBOT: robot.name}},
         "kustomize": {"dir": robot_path(robot.name)}}
        for robot in robots
    ]
    customizations.append({"name": "not-a-robot", "clusterSelector": {}, "doNotDeploy": True})
    document = {
        "labels": {"app.kubernetes.io/part-of": project},
        "targetCustomizations": customizations,
        "rolloutStrategy": {
            "maxUnavailable": 0,
            "maxUnavailablePartitions": 0,
            "partitions": [{"name": wave, "maxUnavailable": 0, "clusterSelector": _in(names)}
                           for wave, names in waves_in_order(robots)],
        },
    }
    return dump([document])


def application_set(robots: Sequence[RobotTarget], project: str, *, repository: str | None,
                    path: str = "", revision: str = "HEAD") -> str:
    """Argo CD's ApplicationSet of the fleet (``argoproj.io/v1alpha1``), RollingSync steps = the waves."""
    prefix = f"{path.strip('/')}/" if path.strip("/") else ""
    elements = [{"robot": r.name, "wave": r.wave, "path": f"{prefix}{robot_path(r.name)}",
                 "namespace": namespace(r.name)} for r in robots]
    steps = [{"matchExpressions": [{"key": LABEL_WAVE, "operator": "In", "values": [wave]}]}
             for wave, _ in waves_in_order(robots)]
    document = {
        "apiVersion": "argoproj.io/v1alpha1",
        "kind": "ApplicationSet",
        "metadata": {"name": f"{project}-robots", "namespace": "argocd"},
        "spec": {
            "goTemplate": True,
            "goTemplateOptions": ["missingkey=error"],
            "generators": [{"list": {"elements": elements}}],
            "strategy": {"type": "RollingSync", "rollingSync": {"steps": steps}},
            "template": {
                "metadata": {"name": f"{project}-{{{{.robot}}}}",
                             "labels": {LABEL_ROBOT: "{{.robot}}", LABEL_WAVE: "{{.wave}}"}},
                "spec": {
                    "project": "default",
                    "source": {"repoURL": repository or NO_REPOSITORY, "targetRevision": revision,
                               "path": "{{.path}}"},
                    "destination": {"name": "{{.robot}}", "namespace": "{{.namespace}}"},
                    "syncPolicy": {"syncOptions": ["ServerSideApply=true"]},
                },
            },
        },
    }
    return dump([document])
