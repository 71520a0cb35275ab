"""A small model of how Rancher Fleet rolls a bundle out, to run an exported ``fleet.yaml`` through it.

It follows Fleet's own code, not robocore's idea of it (rancher/fleet, read 2026-12):

* ``internal/cmd/controller/target/partition.go`` (``UpdatePartitions``, ``updateDeploymentFromStaged``): partitions
  in order; a BundleDeployment moves to the staged deployment only while the bundle's unavailable count is below
  the bundle's ``maxUnavailable`` *and* its partition's count below the partition's (or when it is unavailable
  itself); the loop stops after the partition that makes the unavailable partitions exceed
  ``maxUnavailablePartitions``; a new BundleDeployment is created for at most ``maxNew`` (50) targets a pass.
* ``internal/cmd/controller/target/rollout.go`` (``manualPartition``): a partition's targets are the clusters its
  selector matches; its ``maxUnavailable`` falls back to the bundle's; a cluster in no partition is never updated.
* ``internal/cmd/controller/target/status.go`` (``limit``, ``isUnavailable``, ``upToDate``,
  ``updateStatusAndCheckUnavailable``): an integer stays what it is (0 stays 0), a percentage is at least 1, the
  default is 100 %; a deployment is unavailable when not applied or not ready; a partition is unavailable when
  more of its targets than its ``maxUnavailable`` are unavailable or not up to date.
* The bundle's counts are reset before each pass (``internal/cmd/controller/reconciler``, ``resetStatus``).
* The agent (``internal/cmd/agent/deployer/deployer.go``, ``internal/helmdeployer/install.go``): every bundle is a
  Helm release; the deployment counts as applied (``appliedDeploymentID``) only once the Helm upgrade returned.
  With ``helm.timeoutSeconds`` the upgrade waits with Helm's status watcher: every object kstatus-Current, and with
  ``helm.waitForJobs`` every Job *completed* (helm, ``internal/statusreaders/job_status_reader.go``); a wait that
  never ends well fails at the timeout, and the deployment stays not applied, or applied and not ready. Without
  the wait the upgrade returns at once. ``ready`` is then kstatus on each object (``monitor/updatestatus.go``,
  ``summary/summarizers.go``): a Job is Current as soon as it has *started* (kubernetes-sigs/cli-utils,
  ``pkg/kstatus/status/core.go``, ``jobConditions``), Failed once failed.
* Targets (Fleet's documentation, "Mapping to Downstream Clusters"): ``overrideTargets`` in fleet.yaml replace the
  GitRepo's ``targets``; with neither, the cluster group ``default`` is the target; the first
  ``targetCustomizations`` entry that matches a targeted cluster applies, and ``doNotDeploy`` leaves it out.

The agent side is one function (:func:`agent`); what the robot's objects report is the test's (:class:`Objects`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

DEFAULT_LIMIT = "100%"
MAX_NEW = 50


@dataclass
class Cluster:
    """A downstream cluster and its BundleDeployment of the bundle (``deployment`` None: none yet)."""

    name: str
    labels: dict[str, str]
    groups: tuple[str, ...] = ()
    deployment: str | None = None  # spec.deploymentID
    staged: str = ""  # spec.stagedDeploymentID
    applied: str = ""  # status.appliedDeploymentID
    ready: bool = False  # status.ready
    history: list[str] = field(default_factory=list)  # every deployment ID it was moved to, in order


def matches(selector: Mapping[str, Any] | None, labels: Mapping[str, str]) -> bool:
    """A Kubernetes label selector (matchLabels, matchExpressions In/NotIn/Exists/DoesNotExist); {} matches all."""
    if selector is None:
        return False
    if any(labels.get(k) != v for k, v in selector.get("matchLabels", {}).items()):
        return False
    for expression in selector.get("matchExpressions", []):
        key, operator, values = expression["key"], expression["operator"], expression.get("values", [])
        ok = {"In": key in labels and labels[key] in values, "NotIn": labels.get(key) not in values,
              "Exists": key in labels, "DoesNotExist": key not in labels}[operator]
        if not ok:
            return False
    return True


def limit(count: int, *values: int | str | None) -> int:
    """Fleet's ``limit``: the first value given; an int as is (within 0..count), a percentage of ``count`` rounded
    down but >= 1."""
    if count <= 0:
        return 1
    value = next((v for v in values if v is not None), DEFAULT_LIMIT)
    if isinstance(value, int):
        return min(max(value, 0), count)
    if value.isdigit() and int(value) > 0:
        return int(value)
    if not value.endswith("%"):
        raise ValueError(f"invalid maxUnavailable, must be int or percentage: {value}")
    percent = float(value.rstrip("%"))
    return max(int(count * percent) // 100, 1) if percent > 0 else 1


def targets(fleet_yaml: Mapping[str, Any], clusters: Sequence[Cluster],
            gitrepo_targets: Sequence[Mapping[str, Any]] = ()) -> list[Cluster]:
    """The clusters that get a BundleDeployment: targeted, and not left out by a ``doNotDeploy`` customization."""
    chosen = fleet_yaml.get("overrideTargets") or list(gitrepo_targets) or [{"clusterGroup": "default"}]
    out = []
    for cluster in clusters:
        if not any(matches(t.get("clusterSelector"), cluster.labels) or t.get("clusterGroup") in cluster.groups
                   for t in chosen):
            continue
        custom = next((c for c in fleet_yaml.get("targetCustomizations", [])
                       if matches(c.get("clusterSelector"), cluster.labels)), None)
        if custom is None or not custom.get("doNotDeploy"):
            out.append(cluster)
    return out


def _unavailable(cluster: Cluster) -> bool:
    return cluster.deployment is not None and (cluster.applied != cluster.deployment or not cluster.ready)


def _up_to_date(cluster: Cluster, wanted: str) -> bool:
    return cluster.deployment == wanted and cluster.staged == wanted and cluster.applied == wanted


def reconcile(fleet_yaml: Mapping[str, Any], clusters: Sequence[Cluster], wanted: str) -> None:
    """One pass of Fleet's bundle controller over ``clusters`` (already targeted) for deployment ID ``wanted``."""
    rollout = fleet_yaml.get("rolloutStrategy") or {}
    bundle_max = limit(len(clusters), rollout.get("maxUnavailable"))
    bundle_unavailable = sum(_unavailable(c) for c in clusters)
    partitions = []
    for definition in rollout.get("partitions", []):
        members = [c for c in clusters if matches(definition.get("clusterSelector"), c.labels)]
        maximum = limit(len(members), definition.get("maxUnavailable"), rollout.get("maxUnavailable"))
        partitions.append((members, maximum))
    if not partitions:  # fewer than 200 targets and no partitions: one partition of all
        partitions = [(list(clusters), bundle_max)]
    max_partitions = limit(len(partitions), rollout.get("maxUnavailablePartitions"), 0)
    new = unavailable_partitions = 0
    for members, maximum in partitions:
        partition_unavailable = sum(_unavailable(c) for c in members)
        for cluster in members:
            if cluster.deployment is None and new < MAX_NEW:
                new += 1
                cluster.deployment = ""
            if cluster.deployment is not None:
                cluster.staged = wanted
        for cluster in members:
            if cluster.deployment is None or cluster.deployment == cluster.staged:
                continue
            if ((bundle_unavailable < bundle_max or _unavailable(cluster))
                    and (partition_unavailable < maximum or _unavailable(cluster))):
                if not _unavailable(cluster):
                    bundle_unavailable += 1
                    partition_unavailable += 1
                cluster.deployment = cluster.staged
                cluster.history.append(cluster.staged)
        if sum(not _up_to_date(c, wanted) or _unavailable(c) for c in members) > maximum:
            unavailable_partitions += 1
        if unavailable_partitions > max_partitions:
            break


@dataclass(frozen=True)
class Objects:
    """What a cluster's objects of one deployment report at one look: its workloads (DaemonSets) all ready, and its
    Job ``"running"``, ``"complete"`` or ``"failed"`` (None: no Job)."""

    workloads: bool
    job: str | None = None


#: What ``cluster``'s objects of ``deployment`` report now (a bool: workloads ready, no Job).
Observe = Callable[[Cluster, str], "Objects | bool"]


def agent(fleet_yaml: Mapping[str, Any], clusters: Sequence[Cluster], observe: Observe) -> None:
    """Every cluster's agent deploys its deployment (a Helm upgrade, waiting as fleet.yaml's ``helm`` says) and
    reports whether it is applied and ready."""
    helm = fleet_yaml.get("helm") or {}
    waits = int(helm.get("timeoutSeconds") or 0) > 0
    for cluster in clusters:
        if not cluster.deployment:
            continue
        seen = observe(cluster, cluster.deployment)
        objects = seen if isinstance(seen, Objects) else Objects(seen)
        current = objects.workloads and objects.job != "failed"  # kstatus: a started Job is Current
        if waits:
            done = objects.workloads and (objects.job in (None, "complete") if helm.get("waitForJobs") else current)
            if not done:  # the upgrade still waits (or failed at its timeout): not applied
                cluster.ready = False
                continue
        cluster.applied = cluster.deployment
        cluster.ready = current


def roll_out(fleet_yaml: Mapping[str, Any], clusters: Sequence[Cluster], wanted: str, observe: Observe,
             passes: int = 50) -> list[list[str]]:
    """Controller pass, agents, again, until nothing changes: the clusters moved to ``wanted`` in each pass."""
    def state() -> list[tuple[str | None, str, str, bool]]:
        return [(c.deployment, c.staged, c.applied, c.ready) for c in clusters]

    steps: list[list[str]] = []
    for _ in range(passes):
        before, deployments = state(), {c.name: c.deployment for c in clusters}
        reconcile(fleet_yaml, clusters, wanted)
        agent(fleet_yaml, clusters, observe)
        if state() == before:
            break
        steps.append([c.name for c in clusters if c.deployment != deployments[c.name] and c.deployment == wanted])
    return [step for step in steps if step]
