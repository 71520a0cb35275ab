"""One robot's kustomize overlay: its namespace, labels, release images and node pinning over its model's base (pure).

``robots/<robot>/`` changes nothing of the base but these, so that checking one base checks every robot of it
(bench/k8s_export.py proves it on 1000 robots):

* ``namespace: robot-<robot>`` and the Namespace itself, labelled with the Pod Security level its pods need
  (:data:`POD_SECURITY`): ``privileged``, as host network, host IPC and hostPath volumes are refused by both
  ``baseline`` and ``restricted``, which hardened clusters (RKE2, k3s with a Pod Security admission config)
  enforce by default;
* the label :data:`~robocore.plan.kubernetes.names.LABEL_ROBOT` (and the fleet file's labels of the robot)
  on every object and pod;
* ``images``: each logical image name of the base mapped to the release's image, by tag or by digest;
* node pinning: every pod's nodeSelector gains the robot's label, so a pod runs only on that robot's host, even
  in one cluster holding many robots. A ``labels`` entry whose ``fields`` name the nodeSelector, not a patch:
  the same objects, and a fifth less of kustomize's time per robot (bench/k8s_export.py renders 1000 of them);
* the robot's ``ros_domain_id`` when the fleet file gives it another one than robot.yaml.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from robocore.plan.kubernetes.base import KUSTOMIZATION, Base, kustomization
from robocore.plan.kubernetes.names import LABEL_ROBOT, dump, logical_image, namespace

#: The Pod Security Standards labels of a robot's namespace: every pod of a robot uses the host's network (DDS), most
#: its IPC (shared memory) and hostPath volumes (devices, state), which only the ``privileged`` level admits.
POD_SECURITY = {f"pod-security.kubernetes.io/{mode}": "privileged" for mode in ("enforce", "audit", "warn")}


@dataclass(frozen=True)
class ImageRef:
    """A release image: its name (``registry/repository``) and a tag or a digest (``sha256:...``)."""

    name: str
    tag: str | None = None
    digest: str | None = None

    def kustomize(self, logical: str) -> dict[str, str]:
        """The kustomize ``images`` entry that maps ``logical`` to this image."""
        entry = {"name": logical, "newName": self.name}
        if self.digest:
            entry["digest"] = self.digest
        elif self.tag:
            entry["newTag"] = self.tag
        return entry

    @property
    def text(self) -> str:
        """``name@digest`` or ``name:tag``."""
        return f"{self.name}@{self.digest}" if self.digest else f"{self.name}:{self.tag}"


#: The release's image of (repository, arch).
ImageSource = Callable[[str, str], ImageRef]


@dataclass(frozen=True)
class RobotTarget:
    """One robot of the fleet: its name, model, wave, free labels, release images and per-robot settings."""

    name: str
    model: str
    wave: str
    images: ImageSource
    labels: Mapping[str, str] = field(default_factory=dict)
    #: The robot's DDS domain when it differs from its model's (None: the model's).
    ros_domain_id: int | None = None


def robot_path(robot: str) -> str:
    """The overlay folder of ``robot``, relative to the export folder."""
    return f"robots/{robot}"


def plan_overlay(target: RobotTarget, base: Base, *, ros2: bool) -> dict[str, str]:
    """The files of ``robots/<robot>/`` (path relative to it -> text)."""
    ns = namespace(target.name)
    labels = {LABEL_ROBOT: target.name, **dict(sorted(target.labels.items()))}
    images = [target.images(repo, arch).kustomize(logical_image(repo, arch)) for repo, arch in base.images]
    pin = {"pairs": {LABEL_ROBOT: target.name},
           "fields": [{"path": "spec/template/spec/nodeSelector", "kind": kind, "create": True}
                      for kind in ("DaemonSet", "Job")]}
    patches: list[dict[str, Any]] = []
    files = {"namespace.yaml": dump([{"apiVersion": "v1", "kind": "Namespace",
                                      "metadata": {"name": ns, "labels": dict(POD_SECURITY)}}])}
    if ros2 and target.ros_domain_id is not None:
        files["domain.yaml"] = dump([{
            "apiVersion": "apps/v1", "kind": "DaemonSet", "metadata": {"name": "any"},
            "spec": {"template": {"spec": {"containers": [
                {"name": "main", "env": [{"name": "ROS_DOMAIN_ID", "value": str(target.ros_domain_id)}]}]}}},
        }])
        patches.append({"path": "domain.yaml", "target": {"kind": "DaemonSet|Job"}})
    document = kustomization(
        namespace=ns,
        resources=["namespace.yaml", f"../../bases/{base.model}"],
        labels=[{"pairs": labels, "includeTemplates": True}, pin],
        images=images,
        **({"patches": patches} if patches else {}),
    )
    files[KUSTOMIZATION] = dump([document])
    return files
