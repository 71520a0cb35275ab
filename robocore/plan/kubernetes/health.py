"""robocore's health gate inside the cluster: what makes a robot count as healthy to Rancher Fleet and Argo CD (pure).

Both controllers call a robot ready when its objects are: a DaemonSet when every pod it wants is available, which
holds for a DaemonSet that wants none (its nodeSelector matches no node). A Job is ready to Argo CD once it has
completed, but to Fleet's agent (kstatus) as soon as it has started; so the exported fleet.yaml has Fleet's Helm
upgrade wait for the Job to complete (``helm.waitForJobs``, :mod:`~robocore.plan.kubernetes.gitops`). The
gate robocore's Swarm rollout runs (every container up for ``rollout.health.running`` seconds, then the robot's
graph holds ``health.nodes`` and a message was heard on each of ``health.heard``) becomes, in each model's base:

* ``minReadySeconds: running`` on every DaemonSet: a pod counts as available only after that long without a
  restart, and a DaemonSet (so the robot) only when all its pods are;
* a Job ``health-<hash>`` on the host of the first discovery server, in the release's base image, with two steps.
  The init container (``robocore/resources/k8s-daemonsets``) waits until every DaemonSet of the robot's namespace
  has a pod scheduled, updated and available: a DaemonSet that schedules nothing (an unlabelled node, a typo, the
  wrong arch) fails the gate. Then the same graph probe as the Swarm gate (``fleet-probe``, or ``fleet-probe-ros1``
  for a ROS 1 master) checks ``health.nodes`` and ``health.heard``. Each step may take ``timeouts.robot``
  seconds; the Job is never retried (``backoffLimit: 0``), so a robot that fails its gate stays not ready, and
  its rollout stays stopped, until a new release or until someone deletes the Job to check again. A Job's pod
  template cannot change, so the Job's name is a hash of everything its pods hold (the base, the release's images,
  the gate, the robots' own settings): a new release is a new Job, and the controllers prune the old one.
* a ServiceAccount, Role and RoleBinding ``robocore-health`` that let the Job get and list the DaemonSets of the
  robot's namespace, nothing else.

``rollout.timeouts.wave`` has no counterpart: neither controller bounds a wave's time; a robot that fails its gate
stops the rollout in both.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from robocore import resources
from robocore.plan import naming
from robocore.plan.discovery.base import in_folder
from robocore.plan.kubernetes.names import LABEL_ARCH, LABEL_HOST, LABEL_MODEL, LABEL_ROLE, LABEL_WORKLOAD
from robocore.plan.kubernetes.pods import OFFLINE_TAINTS, PodContext, environment
from robocore.plan.swarm_services import probe_resource

if TYPE_CHECKING:
    from robocore.config.fleet import Fleet
    from robocore.config.model import Robot

#: The name of the ServiceAccount, Role, RoleBinding and generated ConfigMap (the scripts) of the gate.
HEALTH = "robocore-health"
#: Where the Job's containers find the scripts.
SCRIPTS = "/robocore/health"
#: The resource file of the workload check (the Job's first step).
DAEMONSETS = "k8s-daemonsets"
ROLE_HEALTH = "health"


@dataclass(frozen=True)
class Gate:
    """The fleet file's ``rollout.health`` and ``rollout.timeouts.robot``, as the cluster's gate uses them."""

    running: float = 10
    nodes: tuple[str, ...] = ()
    heard: tuple[str, ...] = ()
    timeout: float = 120

    @classmethod
    def of(cls, fleet: Fleet | None) -> Gate:
        """The gate of ``fleet`` (the defaults without a fleet file)."""
        if fleet is None:
            return cls()
        health, timeouts = fleet.rollout.health, fleet.rollout.timeouts
        return cls(running=float(health.running), nodes=tuple(health.nodes), heard=tuple(health.heard),
                   timeout=float(timeouts.robot))

    @property
    def min_ready_seconds(self) -> int:
        """``running`` as a DaemonSet's ``minReadySeconds`` (whole seconds, rounded up)."""
        return math.ceil(self.running)

    @property
    def deadline(self) -> int:
        """The Job's ``activeDeadlineSeconds``: its two steps of ``timeout`` each, and a minute for its pod to
        start (the image pull included); past it, Kubernetes fails the Job whatever its steps do."""
        return math.ceil(2 * self.timeout) + 60


def scripts(robot: Robot) -> dict[str, str]:
    """The files of the gate's ConfigMap: the workload check and the graph probe of the robot's discovery kind."""
    return {"daemonsets.py": resources.read(DAEMONSETS).decode(),
            "probe.py": resources.read(probe_resource(robot)).decode()}


def job_name(key: Sequence[str]) -> str:
    """``health-<hash>`` of ``key`` (every text the Job's pods depend on)."""
    digest = hashlib.sha256("\0".join(key).encode()).hexdigest()[:10]
    return f"health-{digest}"


def access() -> list[dict[str, Any]]:
    """The ServiceAccount of the Job and its right to read the DaemonSets of the robot's namespace."""
    return [
        {"apiVersion": "v1", "kind": "ServiceAccount", "metadata": {"name": HEALTH}},
        {"apiVersion": "rbac.authorization.k8s.io/v1", "kind": "Role", "metadata": {"name": HEALTH},
         "rules": [{"apiGroups": ["apps"], "resources": ["daemonsets"], "verbs": ["get", "list"]}]},
        {"apiVersion": "rbac.authorization.k8s.io/v1", "kind": "RoleBinding", "metadata": {"name": HEALTH},
         "roleRef": {"apiGroup": "rbac.authorization.k8s.io", "kind": "Role", "name": HEALTH},
         "subjects": [{"kind": "ServiceAccount", "name": HEALTH}]},
    ]


def job(name: str, robot: Robot, host: str, gate: Gate, context: PodContext, *, host_ipc: bool) -> dict[str, Any]:
    """The health Job ``name`` of a robot on ``host`` (its first discovery server's; see the module docstring)."""
    from robocore.plan import discovery

    kind = discovery.for_robot(robot)
    timeout = f"{gate.timeout:g}"
    args = ["python3", f"{SCRIPTS}/probe.py", "--timeout", timeout]
    for node in gate.nodes:
        args += ["--node", node]
    for topic in gate.heard:
        args += ["--heard", topic]
    mounts = [{"name": "scripts", "mountPath": SCRIPTS, "readOnly": True}]
    volumes: list[dict[str, Any]] = [{"name": "scripts", "configMap": {"name": HEALTH}}]
    probe_mounts = list(mounts)
    if context.dds_config_map is not None:
        probe_mounts.append({"name": "dds", "mountPath": naming.CONTAINER_DDS, "readOnly": True})
        volumes.append({"name": "dds", "configMap": {"name": context.dds_config_map}})
    variables = kind.observer_environment(host, files=in_folder(naming.CONTAINER_DDS))
    labels = {LABEL_WORKLOAD: "health", LABEL_MODEL: context.model, LABEL_ROLE: ROLE_HEALTH, LABEL_HOST: host}
    pod: dict[str, Any] = {
        "serviceAccountName": HEALTH,
        "restartPolicy": "Never",
        "hostNetwork": True,
        "dnsPolicy": "ClusterFirstWithHostNet",
    }
    if host_ipc:
        pod["hostIPC"] = True
    pod["nodeSelector"] = {LABEL_HOST: host, LABEL_ARCH: context.arch}
    pod["tolerations"] = [{"key": key, "operator": "Exists", "effect": "NoExecute"} for key in OFFLINE_TAINTS]
    pod["initContainers"] = [{
        "name": "workloads", "image": context.wait_image, "imagePullPolicy": "IfNotPresent",
        "command": ["python3", f"{SCRIPTS}/daemonsets.py", "--timeout", timeout], "volumeMounts": mounts,
    }]
    pod["containers"] = [{
        "name": "main", "image": context.wait_image, "imagePullPolicy": "IfNotPresent",
        "command": [naming.ENTRYPOINT], "args": args, "env": environment(variables, context),
        "volumeMounts": probe_mounts,
    }]
    pod["volumes"] = volumes
    return {
        "apiVersion": "batch/v1",
        "kind": "Job",
        "metadata": {"name": name, "labels": dict(labels)},
        "spec": {
            "backoffLimit": 0,
            "activeDeadlineSeconds": gate.deadline,
            "template": {"metadata": {"labels": labels}, "spec": pod},
        },
    }
