"""One robocore container as one Kubernetes DaemonSet: the pod settings ROS needs, from a ContainerSpec (pure).

The container itself (image, command, environment, IPC, devices, GPUs, privileges) is what
:mod:`robocore.plan.containers` plans for ``run``; this module only says it in Kubernetes terms:

* **DaemonSet, not Deployment.** Each workload's nodeSelector matches one node (a robot's host, by
  robocore's node labels), so it runs at most one pod there: never two copies of one ROS node. A
  DaemonSet update stops the old pod before starting the new one (``maxSurge: 0``), and its pods
  tolerate ``unreachable``/``not-ready`` with no time limit, so a robot that drops off the network keeps
  its nodes running (a Deployment's pods are evicted after 300 s). The tolerations are also written out,
  so that they are visible and survive a change of controller.
* **Host network** with ``dnsPolicy: ClusterFirstWithHostNet``: DDS and TCPROS need the host's
  address, and the cluster's DNS still resolves the discovery servers' Service names.
* **Shared memory** as robot.yaml says: ``hostIPC`` when ``transport: shm`` (what ``ipc: host`` is
  under Docker), none with ``transport: udp`` (the DDS profiles then keep data off shared memory).
* **The process tree.** ``shareProcessNamespace`` makes the pod's pause process PID 1, which reaps
  orphans and lets the node (or discovery server) handle SIGTERM, as Docker's ``--init`` does for robocore's
  containers. The pause process signals no process group: the variable that asks Docker's init to do so
  (``naming.INIT_SIGNALS_GROUP``) is left out, and a stopped discovery server's tool ends at once, server with it.
* **ROS 1**: ``ROS_IP`` is the node's address (``status.hostIP``), for the TCPROS callbacks.
* **Volumes**: the install tree and the read-only project volumes are in the fleet release's image, so the pod
  mounts neither; a writable project volume is a folder under the host's mount root (made when missing), an
  absolute one the host's own path.
* **Waiting for discovery**: an init container waits until the discovery Services' names resolve (Fast DDS ignores
  ``ROS_DISCOVERY_SERVER`` when a name does not), and a component in robocore's image waits again at each start
  (:data:`START_SCRIPT`), as a container the kubelet restarts after a crash runs no init container. A component
  of a robot.yaml ``image:`` keeps that image's own entrypoint, so only the init container waits for it.
* **Resources**: robot.yaml's ``resources`` as the container's requests and limits; ``priority: critical`` as
  ``priorityClassName: system-node-critical`` (evicted last; :mod:`robocore.plan.resources`).
* **Devices**: ``privileged`` and a ``hostPath`` per device (a device cgroup rule has no pod form);
  GPUs: ``runtimeClassName: nvidia`` and every GPU visible, like ``--gpus all``.

Kubernetes expands ``$(NAME)`` in commands and environment values; every ``$`` is doubled, so the
container gets exactly what ``run`` gives it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from robocore.plan import naming
from robocore.plan.containers import ContainerSpec
from robocore.plan.kubernetes.names import (
    LABEL_ARCH,
    LABEL_COMPONENT,
    LABEL_HOST,
    LABEL_MODEL,
    LABEL_ROLE,
    LABEL_WORKLOAD,
    STATE_ROOT,
)
from robocore.plan.resources import CRITICAL_PRIORITY_CLASS, pod_resources

#: Node conditions a robot's pods ride out, however long they last.
OFFLINE_TAINTS = ("node.kubernetes.io/not-ready", "node.kubernetes.io/unreachable")
#: The init container of a component: waits until every discovery Service name resolves, so that the middleware
#: never starts without its servers (Fast DDS ignores ``ROS_DISCOVERY_SERVER`` when a name does not resolve).
#: Fixed text; the names come as arguments.
WAIT_SCRIPT = 'for name in "$@"; do until getent hosts "$name" >/dev/null; do sleep 1; done; done'
#: The start of a component in robocore's image: wait for the discovery Service names (the arguments before ``--``),
#: then exec the component (the arguments after). The init container waits at pod start; this wait also holds when
#: the kubelet restarts the container after a crash, which runs no init container again. Fixed text.
START_SCRIPT = ('while [ "$#" -gt 0 ] && [ "$1" != -- ]; do until getent hosts "$1" >/dev/null; do sleep 1; done; '
                'shift; done; shift; exec "$@"')
#: The environment keys a ROS 1 node advertises its address with; on Kubernetes, the node's address.
ADVERTISED = ("ROS_HOSTNAME", "ROS_IP", "ROS_IPV6")


@dataclass(frozen=True)
class PodContext:
    """What a workload needs beyond its ContainerSpec: where it runs and what the base around it holds."""

    model: str
    arch: str
    image: str  # the logical image name of the container (names.logical_image)
    wait_image: str  # the logical name of the base image, for the init container
    dds_config_map: str | None  # the ConfigMap of the discovery kind's files (None: the kind has none)
    discovery_names: tuple[str, ...]  # the discovery Service names a component waits for
    advertised_names: frozenset[str]  # names a ROS 1 node would advertise; replaced by the node's address
    user_mounts: int = 0  # how many of the spec's last mounts are robot.yaml ``volumes``
    #: The hosts' mount roots: a writable project volume is a folder robocore keeps there (made when missing).
    deploy_roots: tuple[str, ...] = ()
    #: Container paths of the read-only project volumes, which the fleet release's image carries: not mounted.
    baked: frozenset[str] = frozenset()
    #: Seconds a pod must run without a restart before it counts as available (the gate's ``health.running``).
    min_ready: int = 0


def escape(text: str) -> str:
    """``text`` with every ``$`` doubled: Kubernetes' escape of ``$(NAME)`` expansion."""
    return text.replace("$", "$$")


def environment(variables: Mapping[str, str], context: PodContext, *, gpus: bool = False) -> list[dict[str, Any]]:
    """A container's ``env`` list from robocore's environment of it: ``$`` escaped, Docker's init variable left out,
    a ROS 1 node's advertised address replaced by the node's (``status.hostIP``), every GPU visible with ``gpus``."""
    env = dict(variables)
    env.pop(naming.INIT_SIGNALS_GROUP, None)  # no such init in a pod (module docstring)
    ros1_address = env.get("ROS_HOSTNAME") in context.advertised_names
    if ros1_address:
        for key in ADVERTISED:
            env.pop(key, None)
    if gpus:
        env.setdefault("NVIDIA_VISIBLE_DEVICES", "all")
    out: list[dict[str, Any]] = [{"name": k, "value": escape(v)} for k, v in sorted(env.items())]
    if ros1_address:
        out.append({"name": "ROS_IP", "valueFrom": {"fieldRef": {"fieldPath": "status.hostIP"}}})
    return out


def _volumes(spec: ContainerSpec, context: PodContext) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """(volumes, volumeMounts) of the spec's mounts and devices."""
    volumes: list[dict[str, Any]] = []
    mounts: list[dict[str, Any]] = []
    user_start = len(spec.mounts) - context.user_mounts

    def add(volume: dict[str, Any], target: str, read_only: bool) -> None:
        name = f"v{len(volumes)}"
        volumes.append({"name": name, **volume})
        mount: dict[str, Any] = {"name": name, "mountPath": target}
        if read_only:
            mount["readOnly"] = True
        mounts.append(mount)

    for position, mount in enumerate(spec.mounts):
        if mount.target == naming.CONTAINER_INSTALL or (position >= user_start and mount.target in context.baked):
            continue  # the install tree and the read-only project files are in the fleet release's image
        if mount.target == naming.CONTAINER_DDS:
            if context.dds_config_map is not None:
                add({"configMap": {"name": context.dds_config_map}}, mount.target, True)
            continue
        if mount.is_named_volume:  # the discovery server's state (user named volumes are refused)
            add({"hostPath": {"path": f"{STATE_ROOT}/{context.model}/{spec.service}", "type": "DirectoryOrCreate"}},
                mount.target, mount.read_only)
            continue
        # the robot host's own path: robot.yaml's, or a folder under the host's mount root that robocore made
        volume: dict[str, Any] = {"path": mount.source}
        if position >= user_start and not mount.read_only:
            volume["type"] = "DirectoryOrCreate" if mount.source.startswith(context.deploy_roots) else ""
        add({"hostPath": {k: v for k, v in volume.items() if v}}, mount.target, mount.read_only)
    for device in spec.devices:
        parts = device.split(":")
        add({"hostPath": {"path": parts[0]}}, parts[1] if len(parts) > 1 and parts[1] else parts[0], False)
    return volumes, mounts


def _container(spec: ContainerSpec, context: PodContext) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    volumes, mounts = _volumes(spec, context)
    container: dict[str, Any] = {"name": "main", "image": context.image, "imagePullPolicy": "IfNotPresent"}
    if spec.entrypoint is not None and spec.role == naming.ROLE_COMPONENT and context.discovery_names:
        container["command"] = ["sh", "-c", escape(START_SCRIPT), "robocore-start", *context.discovery_names, "--",
                                *(escape(a) for a in spec.entrypoint)]
    elif spec.entrypoint is not None:
        container["command"] = [escape(a) for a in spec.entrypoint]
    if spec.command is not None:
        container["args"] = [escape(a) for a in spec.command]
    container["env"] = environment(dict(spec.environment), context, gpus=bool(spec.gpus))
    if spec.limits is not None and pod_resources(spec.limits):
        container["resources"] = pod_resources(spec.limits)
    if spec.privileged or spec.devices:
        container["securityContext"] = {"privileged": True}
    if mounts:
        container["volumeMounts"] = mounts
    return container, volumes


def daemon_set(name: str, spec: ContainerSpec, context: PodContext) -> dict[str, Any]:
    """The DaemonSet ``name`` that runs ``spec`` on its host (see the module docstring for each setting)."""
    labels = {LABEL_WORKLOAD: name, LABEL_MODEL: context.model, LABEL_ROLE: spec.role, LABEL_HOST: spec.host}
    if spec.role == naming.ROLE_COMPONENT:
        labels[LABEL_COMPONENT] = spec.service
    container, volumes = _container(spec, context)
    pod: dict[str, Any] = {
        "hostNetwork": True,
        "dnsPolicy": "ClusterFirstWithHostNet",
    }
    if spec.ipc_mode == "host":
        pod["hostIPC"] = True
    if spec.role in naming.MANAGED_ROLES:
        pod["shareProcessNamespace"] = True
    if spec.gpus:
        pod["runtimeClassName"] = "nvidia"
    if spec.limits is not None and spec.limits.critical:
        pod["priorityClassName"] = CRITICAL_PRIORITY_CLASS
    pod["nodeSelector"] = {LABEL_HOST: spec.host, LABEL_ARCH: context.arch}
    pod["tolerations"] = [{"key": key, "operator": "Exists", "effect": "NoExecute"} for key in OFFLINE_TAINTS]
    if spec.role == naming.ROLE_COMPONENT and context.discovery_names:
        pod["initContainers"] = [{
            "name": "wait-discovery", "image": context.wait_image, "imagePullPolicy": "IfNotPresent",
            "command": ["sh", "-c", escape(WAIT_SCRIPT), "wait-discovery", *context.discovery_names],
        }]
    pod["containers"] = [container]
    if volumes:
        pod["volumes"] = volumes
    return {
        "apiVersion": "apps/v1",
        "kind": "DaemonSet",
        "metadata": {"name": name, "labels": dict(labels)},
        "spec": {
            "selector": {"matchLabels": {LABEL_WORKLOAD: name}},
            **({"minReadySeconds": context.min_ready} if context.min_ready else {}),
            "updateStrategy": {"type": "RollingUpdate", "rollingUpdate": {"maxUnavailable": 1, "maxSurge": 0}},
            "template": {"metadata": {"labels": labels}, "spec": pod},
        },
    }


def headless_service(name: str, host: str, ports: Sequence[tuple[int, str]], model: str) -> dict[str, Any]:
    """The headless Service ``name`` whose address is the node of ``host``'s discovery servers: their pods use the
    host network, so the Service's DNS name resolves to the host's address. Published before the pods are ready,
    so that the name resolves as soon as a server is scheduled."""
    return {
        "apiVersion": "v1",
        "kind": "Service",
        "metadata": {"name": name, "labels": {LABEL_MODEL: model, LABEL_HOST: host}},
        "spec": {
            "clusterIP": "None",
            "publishNotReadyAddresses": True,
            "selector": {LABEL_ROLE: naming.ROLE_DISCOVERY, LABEL_HOST: host},
            "ports": [{"name": f"{protocol.lower()}-{port}", "port": port, "protocol": protocol}
                      for port, protocol in ports],
        },
    }
