"""The kustomize base of one robot model (one robot.yaml): every workload of the robot, for any robot of it (pure).

``bases/<model>/`` holds one DaemonSet per component and per discovery server (or the ROS 1 master),
the headless Services through which the nodes reach the servers, and the discovery kind's files (the
DDS profiles) as a generated ConfigMap mounted where ``run`` mounts them. The containers are the ones
:mod:`robocore.plan.containers` plans, asked of a *cluster view* of the robot in which each host's
address is the name of its discovery Service: the discovery kind then writes those names into
``ROS_DISCOVERY_SERVER``, the profiles and ``ROS_MASTER_URI``, and the base holds nothing that differs
between two robots of the model. Images are logical names (:func:`~robocore.plan.kubernetes.names.logical_image`)
that each robot's overlay maps to the release it runs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from robocore.config.model import DockerAccess, Robot
from robocore.plan import discovery, naming
from robocore.plan.containers import component_spec, discovery_spec
from robocore.plan.fleet_release import baked_volumes
from robocore.plan.kubernetes import health
from robocore.plan.kubernetes.names import discovery_service, discovery_workload, dump, k8s_name, logical_image
from robocore.plan.kubernetes.pods import PodContext, daemon_set, headless_service
from robocore.project import Project

#: The name of the generated ConfigMap of the discovery kind's files (kustomize adds a content hash, so a changed
#: profile rolls the pods that mount it).
DDS_CONFIG_MAP = "dds"
KUSTOMIZATION = "kustomization.yaml"


@dataclass(frozen=True)
class Base:
    """One model's base: its files (path under ``bases/<model>/`` -> text) and what overlays refer to."""

    model: str
    files: dict[str, str]
    #: (repository, arch) of every image a logical name stands for, sorted.
    images: tuple[tuple[str, str], ...]
    #: (host, arch) of every host that runs a workload, in robot.yaml's order.
    hosts: tuple[tuple[str, str], ...]


def cluster_view(project: Project) -> Project:
    """``project`` with each host's address replaced by the name of its discovery Service, every host remote."""
    robot = project.robot
    hosts = [h.model_copy(update={"ip": discovery_service(h.name), "docker": DockerAccess.ssh}) for h in robot.hosts]
    return Project(root=project.root, robot=robot.model_copy(update={"hosts": hosts}))


def kustomization(**fields: Any) -> dict[str, Any]:
    """A kustomization document with ``fields`` after its apiVersion and kind."""
    return {"apiVersion": "kustomize.config.k8s.io/v1beta1", "kind": "Kustomization", **fields}


def plan_base(project: Project, model: str, gate: health.Gate | None = None, release: Sequence[str] = ()) -> Base:
    """The base of ``project``'s robot under the name ``model`` (a DNS label; refusals checked before), with the health
    gate ``gate`` (:mod:`~robocore.plan.kubernetes.health`). ``release``: every text the robots' overlays add to
    the pods (the release's images, the robots' own settings), so that the health Job's name changes with them."""
    gate = gate or health.Gate()
    view = cluster_view(project)
    robot: Robot = view.robot
    kind = discovery.for_robot(robot)
    files = kind.files()
    base_repo = naming.base_image(robot, project.name)
    servers = kind.servers()
    server_hosts = sorted({s.host for s in servers}, key=[h.name for h in robot.hosts].index)
    names = tuple(discovery_service(h) for h in server_hosts)
    advertised = frozenset(discovery_service(h.name) for h in robot.hosts)
    roots = tuple(sorted({h.deploy_root.rstrip("/") + "/" for h in robot.hosts}))
    images: set[tuple[str, str]] = set()
    out: dict[str, str] = {}
    resources: list[str] = []

    def context(host: str, image: str, user_mounts: int = 0, baked: frozenset[str] = frozenset()) -> PodContext:
        arch = robot.host(host).arch.value
        images.add((base_repo, arch))
        return PodContext(model=model, arch=arch, image=image, wait_image=logical_image(base_repo, arch),
                          dds_config_map=DDS_CONFIG_MAP if files else None, discovery_names=names,
                          advertised_names=advertised, user_mounts=user_mounts, deploy_roots=roots, baked=baked,
                          min_ready=gate.min_ready_seconds)

    for server in servers:
        spec = discovery_spec(view, server.index)
        arch = robot.host(server.host).arch.value
        name = discovery_workload(server.index)
        out[f"{name}.yaml"] = dump([daemon_set(name, spec, context(server.host, logical_image(base_repo, arch)))])
        resources.append(f"{name}.yaml")
    protocol = "TCP" if kind.kind == "rosmaster" else "UDP"
    services = [headless_service(discovery_service(h), h, [(s.port, protocol) for s in servers if s.host == h], model)
                for h in server_hosts]
    out["discovery-services.yaml"] = dump(services)
    resources.append("discovery-services.yaml")
    for component in robot.components:
        spec = component_spec(view, component)
        arch = robot.host(component.runs_on).arch.value
        baked = frozenset(volume.split(":")[1] for volume in baked_volumes(component))
        if component.image and not baked:
            image = spec.image
        else:  # a staged image, or a robot.yaml image that the fleet release's image extends with the baked files
            repo = naming.component_image(robot, project.name, component.name)
            images.add((repo, arch))
            image = logical_image(repo, arch)
        name = k8s_name(component.name)
        ctx = context(component.runs_on, image, user_mounts=len(component.volumes), baked=baked)
        out[f"{name}.yaml"] = dump([daemon_set(name, spec, ctx)])
        resources.append(f"{name}.yaml")
    generators = []
    if files:
        for file_name, text in sorted(files.items()):
            out[f"dds/{file_name}"] = text
        generators.append({"name": DDS_CONFIG_MAP, "files": [f"dds/{n}" for n in sorted(files)]})
    scripts = health.scripts(robot)
    for file_name, text in sorted(scripts.items()):
        out[f"health/{file_name}"] = text
    generators.append({"name": health.HEALTH, "files": [f"health/{n}" for n in sorted(scripts)]})
    gate_host = server_hosts[0] if server_hosts else robot.components[0].runs_on
    key = [*(f"{n}\n{t}" for n, t in sorted(out.items())), repr(gate), *release]
    job = health.job(health.job_name(key), robot, gate_host, gate,
                     context(gate_host, logical_image(base_repo, robot.host(gate_host).arch.value)),
                     host_ipc=kind.transport.shared_memory)
    out["health.yaml"] = dump([*health.access(), job])
    resources.append("health.yaml")
    out[KUSTOMIZATION] = dump([kustomization(resources=resources, configMapGenerator=generators)])
    used = [h for h in robot.hosts_in_use()]
    return Base(model=model, files=out, images=tuple(sorted(images)),
                hosts=tuple((h.name, h.arch.value) for h in used))
