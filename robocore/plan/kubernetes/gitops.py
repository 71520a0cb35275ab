"""The GitOps controllers' files: a Rancher Fleet ``fleet.yaml`` and an Argo CD ApplicationSet, from the waves (pure).

Both take the export folder from a git repository and give each robot its overlay, one cluster per
robot (a k3s cluster on the robot, the shape Google's Cloud Robotics Core chose), wave after wave:

* **Rancher Fleet** (``fleet.yaml`` at the top of the folder, a bundle of kustomize). ``overrideTargets``
  selects the clusters labelled ``robocore.dev/robot=<robot>`` of the export's robots, whatever the GitRepo's
  ``targets`` say (without targets Fleet deploys to the cluster group ``default`` only, and
  ``targetCustomizations`` only customise clusters a target selected). Each gets ``robots/<robot>``
  (``targetCustomizations``); a selected cluster that matches no robot gets nothing (``doNotDeploy``), never the
  root kustomization of every robot. Each wave is a ``rolloutStrategy.partitions`` entry selecting its robots.
  The gate is the bundle's ``maxUnavailable: 1`` (:data:`FLEET_MAX_UNAVAILABLE`): Fleet moves a cluster to the new
  deployment only while fewer than that many of the bundle's clusters are unavailable (not ready, or not yet on
  their deployment), so one robot changes at a time, each after the one before is ready, and a robot that never
  gets ready stops the rollout. ``maxUnavailablePartitions: 0`` makes Fleet stop at the first partition (wave)
  with more than ``maxUnavailable`` robots not ready or not up to date, so the waves go in order. The
  partitions carry no ``maxUnavailable`` of their own (they take the bundle's): an integer 0 stays 0 in Fleet,
  and ``0 < 0`` would never update a ready robot. "Ready" is what Fleet's agent reads from the objects' status
  (kstatus), where a Job counts as ready as soon as it has *started*: the health Job would not hold the next robot.
  So ``helm: {waitForJobs: true, timeoutSeconds: N}``: the agent deploys every bundle as a Helm release, and with
  these its upgrade waits until every object is ready and every Job has *completed* before it reports the
  deployment applied (a robot is unavailable until then); ``N`` (:func:`helm_wait`) outlasts the health Job's own
  deadline, so the Job's verdict, not Helm's clock, decides. (rancher/fleet, internal/cmd/controller/target/
  partition.go, status.go, internal/helmdeployer/install.go; helm, internal/statusreaders/job_status_reader.go;
  kubernetes-sigs/cli-utils, pkg/kstatus/status/core.go; the model in tests/fleet_model.py.)
* **Argo CD** (``argocd/applicationset.yaml``): one Application per robot from a list generator, labelled with its
  wave; the ``RollingSync`` strategy syncs the waves' steps in order, each step waiting for its Applications to be
  healthy, and one Application at a time within a step (``maxUpdate: 1``: an Application counts as updating until it
  is healthy and synced, so one never healthy stops the rollout). The template's ``syncPolicy.automated`` has
  ``prune: true``: the ApplicationSet controller switches automated sync off on RollingSync Applications and syncs
  them itself, pruning only when the template asks (argo-cd, applicationset/progressivesync/progressive_sync.go).
  Progressive syncs are off in Argo CD until ``applicationsetcontroller.enable.progressive.syncs: "true"`` is set in
  ``argocd-cmd-params-cm`` (:data:`PROGRESSIVE_SYNCS`); the file says so in its first lines.
  The cluster of a robot is the Argo CD cluster named after it.
"""

from __future__ import annotations

import base64
import gzip
import json
from collections.abc import Mapping, Sequence
from typing import Any

from robocore.plan.kubernetes.names import HEADER, LABEL_ROBOT, LABEL_WAVE, dump, namespace
from robocore.plan.kubernetes.overlay import RobotTarget, robot_path

#: The repository URL written when none is given: a reserved name that never resolves, so nothing syncs by mistake.
NO_REPOSITORY = "https://git.example.invalid/set-with--git-repo.git"
FLEET_FILE = "fleet.yaml"
APPLICATION_SET = "argocd/applicationset.yaml"
#: The bundle's ``rolloutStrategy.maxUnavailable``: robots changing (or not ready) at one time, fleet-wide.
FLEET_MAX_UNAVAILABLE = 1
#: Seconds Helm's wait outlasts the longest health Job's ``activeDeadlineSeconds``: time to see the Job's verdict.
HELM_WAIT_MARGIN = 60
#: etcd's default limit of one request (``--max-request-bytes``, 1.5 MiB): a Fleet Bundle object must fit in it.
ETCD_REQUEST_LIMIT = 1_572_864
#: Fleet's bundlereader writes every file of a bundle compressed (base64 of gzip) once its plain JSON passes this.
FLEET_COMPRESS_ABOVE = 1_000_000
#: The ConfigMap key without which Argo CD ignores RollingSync (and nothing syncs).
PROGRESSIVE_SYNCS = "applicationsetcontroller.enable.progressive.syncs"
#: The lines above the ApplicationSet: what Argo CD needs before it rolls anything out.
ARGOCD_NOTE = (
    f"# Argo CD ignores the RollingSync strategy below, and then never syncs these Applications, until progressive\n"
    f"# syncs are on: {PROGRESSIVE_SYNCS}: \"true\" in the ConfigMap argocd-cmd-params-cm (namespace argocd),\n"
    "# then restart the argocd-applicationset-controller Deployment (docs/fleets.md, \"On Kubernetes\").\n"
)


def waves_in_order(robots: Sequence[RobotTarget]) -> list[tuple[str, list[str]]]:
    """(wave, robot names) in the order the waves first appear."""
    waves: dict[str, list[str]] = {}
    for robot in robots:
        waves.setdefault(robot.wave, []).append(robot.name)
    return list(waves.items())


def _in(names: Sequence[str]) -> dict[str, Any]:
    return {"matchExpressions": [{"key": LABEL_ROBOT, "operator": "In", "values": list(names)}]}


def helm_wait(deadlines: Sequence[int]) -> dict[str, Any]:
    """fleet.yaml's ``helm`` options that make Fleet's agent wait for the health Jobs (``deadlines``: their
    ``activeDeadlineSeconds``) before it calls a robot's deployment applied."""
    return {"timeoutSeconds": max(deadlines, default=0) + HELM_WAIT_MARGIN, "waitForJobs": True}


def fleet_yaml(robots: Sequence[RobotTarget], project: str, deadlines: Sequence[int] = ()) -> str:
    """Rancher Fleet's ``fleet.yaml`` for the export folder (``deadlines``: the health Jobs'
    ``activeDeadlineSeconds``, which Helm's wait outlasts)."""
    customizations: list[dict[str, Any]] = [
        {"name": robot.name, "clusterSelector": {"matchLabels": {LABEL_ROBOT: robot.name}},
         "kustomize": {"dir": robot_path(robot.name)}}
        for robot in robots
    ]
    customizations.append({"name": "not-a-robot", "clusterSelector": {}, "doNotDeploy": True})
    document = {
        "labels": {"app.kubernetes.io/part-of": project},
        "overrideTargets": [{"name": "robots", "clusterSelector": _in([robot.name for robot in robots])}],
        "targetCustomizations": customizations,
        "helm": helm_wait(deadlines),
        "rolloutStrategy": {
            "maxUnavailable": FLEET_MAX_UNAVAILABLE,
            "maxUnavailablePartitions": 0,
            "partitions": [{"name": wave, "clusterSelector": _in(names)} for wave, names in waves_in_order(robots)],
        },
    }
    return dump([document])


def application_set(robots: Sequence[RobotTarget], project: str, *, repository: str | None,
                    path: str = "", revision: str = "HEAD") -> str:
    """Argo CD's ApplicationSet of the fleet (``argoproj.io/v1alpha1``), RollingSync steps = the waves."""
    prefix = f"{path.strip('/')}/" if path.strip("/") else ""
    elements = [{"robot": r.name, "wave": r.wave, "path": f"{prefix}{robot_path(r.name)}",
                 "namespace": namespace(r.name)} for r in robots]
    steps = [{"matchExpressions": [{"key": LABEL_WAVE, "operator": "In", "values": [wave]}], "maxUpdate": 1}
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
                    # RollingSync turns automated sync off and syncs itself, pruning only when this says prune
                    "syncPolicy": {"automated": {"prune": True}, "syncOptions": ["ServerSideApply=true"]},
                },
            },
        },
    }
    text = dump([document])
    return text.replace(HEADER, HEADER + ARGOCD_NOTE, 1)


def fleet_bundle_bytes(files: Mapping[str, str], limit: int = ETCD_REQUEST_LIMIT) -> int:
    """About how many bytes of JSON the Fleet Bundle of the export folder ``files`` (path -> text) holds, as Fleet's
    bundlereader builds it (rancher/fleet, internal/bundlereader/read.go ``loadBundle``, loaddirectory.go): every
    file a resource (fleet.yaml too), each compressed (base64 of gzip) once the plain bundle passes
    :data:`FLEET_COMPRESS_ABOVE`, and fleet.yaml's targets once more in the spec. Counting stops once past
    ``limit`` (the answer is then only known to be larger), so a fleet of 10,000 robots costs no more than one of
    1,500."""
    targets = len(json.dumps(files.get(FLEET_FILE, "")))
    # JSON of a text: the text, a backslash before each newline and quote, and the keys around it
    plain = targets + sum(len(name) + len(text) + text.count("\n") + text.count('"') + 34
                              for name, text in files.items())
    if plain <= FLEET_COMPRESS_ABOVE:
        return plain
    total = targets
    for name, text in files.items():
        packed = base64.b64encode(gzip.compress(text.encode(), mtime=0))
        total += len(json.dumps(name)) + len(packed) + 55  # the quotes, keys and "encoding":"base64+gz"
        if total > limit:
            break
    return total
