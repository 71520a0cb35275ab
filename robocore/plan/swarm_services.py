"""The Swarm services of a fleet (pure): one per (robot, component) and per discovery server of each robot.

Each robot of a fleet is an instance of robot.yaml (:func:`robocore.plan.fleet.robot_instance`); its containers
are the ones ``run`` would start (:mod:`robocore.plan.containers`, the one description of a container), turned
into Swarm services with what Swarm allows in place of what it does not:

* one task, pinned by robocore's node labels (project, robot, host; the arch is a label too, as a simulated
  arm64 host reports x86_64 as ``node.platform.arch``), updated stop-first: never two copies of a ROS node;
* host networking (DDS discovery and data need the host's addresses; the kernel here has no IPVS either);
* ``/dev/shm`` bind-mounted from the host instead of ``ipc: host`` (Swarm has no ``ipc``): Fast DDS' shared
  memory only needs the shared files;
* the robot's DDS profiles as Swarm configs (immutable, named by content hash) mounted where ``run`` mounts the
  synced files, so that no robot host needs ``sync``;
* images by digest from the release record: the image carries the install tree, a robot runs what was tested;
* the restart policy, environment and named volumes of robot.yaml.

What services cannot carry (devices, privileged, GPUs) is refused before anything changes:
:func:`robocore.plan.fleet.swarm_problems`.

The release a service runs is recorded in its labels (target and previous release, with their images), so that
``fleet status`` and ``fleet rollback`` are true from any machine that reaches the manager.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

from robocore.config.mappings import read_only_project_path
from robocore.config.model import Component, Robot
from robocore.plan import discovery, naming
from robocore.plan.containers import ContainerSpec, Mount, component_spec, discovery_spec
from robocore.plan.discovery.base import in_folder
from robocore.plan.resources import Limits
from robocore.project import Project

#: robocore's node labels: which project, robot and host of robot.yaml a node is, and the arch robocore runs on it.
NODE_PROJECT = "dev.robocore.project"
NODE_ROBOT = "dev.robocore.robot"
NODE_HOST = "dev.robocore.host"
NODE_ARCH = "dev.robocore.arch"

#: Service labels: what robocore keeps in Swarm (so that status is true from any machine).
LABEL_ROBOT = "dev.robocore.robot"
LABEL_RELEASE = "dev.robocore.fleet.release"  # the target release of the service
LABEL_IMAGE = "dev.robocore.fleet.image"  # the target release's image of the service
LABEL_PREVIOUS = "dev.robocore.fleet.previous"  # the release before it ("" when none)
LABEL_PREVIOUS_IMAGE = "dev.robocore.fleet.previous-image"
LABEL_CHANGED = "dev.robocore.fleet.changed"  # when the target last changed (UTC, ISO 8601)
LABEL_HEALTH = "dev.robocore.fleet.health"  # the last gate's verdict: healthy, failed, pending, rolled-back
LABEL_REASON = "dev.robocore.fleet.reason"  # the last gate's reason, in words ("" when it passed)
LABEL_PROBE = "dev.robocore.fleet.probe"  # a one-shot health probe service

#: Longest Swarm service name (a DNS label).
MAX_SERVICE_NAME = 63
#: Docker's restart policies (robot.yaml ``restart``) as Swarm restart conditions.
RESTART_CONDITIONS = {"no": "none", "on-failure": "on-failure", "always": "any", "unless-stopped": "any"}
#: Seconds between restarts of a failed task (Swarm's default is 5 s; a robot node should come back sooner).
RESTART_DELAY = 1.0
#: Where a probe finds its script (a Swarm config).
PROBE_SCRIPT = "/robocore/fleet-probe.py"
#: The health probe of each discovery kind (a file of :mod:`robocore.resources`): an rclpy observer of the Fast DDS
#: graph for ROS 2; for ROS 1, a client of the robot's master (its XML-RPC API for the nodes, rospy for the topics).
PROBE_RESOURCES = {"fastdds": "fleet-probe", "rosmaster": "fleet-probe-ros1"}


@dataclass(frozen=True)
class ConfigFile:
    """A file a service reads, shipped as a Swarm config ``name`` (unique per content), mounted at ``target``."""

    name: str
    target: str
    text: str


@dataclass(frozen=True)
class ServiceSpec:
    """One Swarm service, as data (the adapter turns it into docker-py arguments)."""

    name: str
    robot: str
    component: str  # robot.yaml component, or discovery-<i>, or probe
    role: str  # naming.ROLE_COMPONENT | naming.ROLE_DISCOVERY | "probe"
    image: str  # repository@sha256:... (by digest)
    command: tuple[str, ...] | None
    args: tuple[str, ...] | None
    environment: tuple[tuple[str, str], ...]
    mounts: tuple[Mount, ...]
    configs: tuple[ConfigFile, ...]
    constraints: tuple[str, ...]
    restart: str  # Swarm restart condition: any | on-failure | none
    labels: tuple[tuple[str, str], ...] = field(default=())
    limits: Limits | None = None  # robot.yaml's resources: the service's limits and reservations

    @property
    def label_map(self) -> dict[str, str]:
        """The service's labels as a dict."""
        return dict(self.labels)


@dataclass(frozen=True)
class Release:
    """The images of one release for a fleet: component -> arch -> ``repo@sha256:...``, and the base image per arch
    (what discovery servers and the health probe run)."""

    version: str
    components: Mapping[str, Mapping[str, str]]
    base: Mapping[str, str]

    def image(self, component: str | None, arch: str) -> str | None:
        """The image of ``component`` (None: the base) for ``arch``, or None when the release has none."""
        images = self.base if component is None else self.components.get(component, {})
        return images.get(arch)


def node_labels(project: str, robot: str, host: str, arch: str) -> dict[str, str]:
    """The labels robocore puts on the Swarm node of ``robot``'s ``host``."""
    return {NODE_PROJECT: project, NODE_ROBOT: robot, NODE_HOST: host, NODE_ARCH: arch}


def constraints(project: str, robot: str, host: str, arch: str) -> tuple[str, ...]:
    """Placement constraints pinning a service to exactly ``robot``'s ``host``."""
    return tuple(f"node.labels.{key}=={value}" for key, value in node_labels(project, robot, host, arch).items())


def service_name(project: str, robot: str, part: str) -> str:
    """``<project>-<robot>-<part>``, shortened with a hash when longer than a DNS label allows."""
    name = f"{project}-{robot}-{part}"
    if len(name) <= MAX_SERVICE_NAME:
        return name
    digest = hashlib.sha256(name.encode()).hexdigest()[:10]
    return f"{name[:MAX_SERVICE_NAME - 11].rstrip('-')}-{digest}"


def dds_configs(project: str, robot: str, instance: Robot) -> tuple[ConfigFile, ...]:
    """The robot's DDS profile files as Swarm configs mounted at ``naming.CONTAINER_DDS`` (named by content)."""
    files = discovery.for_robot(instance).files()
    out = []
    for name, text in sorted(files.items()):
        digest = hashlib.sha256(text.encode()).hexdigest()[:12]
        out.append(ConfigFile(name=_config_name(project, robot, name, digest),
                              target=f"{naming.CONTAINER_DDS}/{name}", text=text))
    return tuple(out)


def _config_name(project: str, robot: str, file: str, digest: str) -> str:
    stem = file.replace(".", "-")
    name = f"{project}-{robot}-{stem}-{digest}"
    if len(name) <= 64:
        return name
    return f"{hashlib.sha256(name.encode()).hexdigest()[:40]}-{digest}"


def baked_targets(component: Component) -> set[str]:
    """Where ``component``'s read-only project volumes are mounted: a fleet release carries them in the image."""
    return {volume.split(":")[1] for volume in component.volumes if read_only_project_path(volume) is not None}


def _swarm_mounts(spec: ContainerSpec, baked: set[str]) -> tuple[Mount, ...]:
    """A container's mounts on Swarm: the install tree, the read-only project files (``baked``) and the DDS
    folder come from the image and configs, not from ``sync``; ``/dev/shm`` is shared with the host when the
    container would have had ``ipc: host``."""
    dropped = {naming.CONTAINER_INSTALL, naming.CONTAINER_DDS, *baked}
    mounts = [m for m in spec.mounts if m.target not in dropped]
    if spec.ipc_mode == "host":
        mounts.append(Mount("/dev/shm", "/dev/shm"))
    return tuple(mounts)


def _service(spec: ContainerSpec, *, project: str, robot: str, arch: str, image: str, role: str,
             configs: tuple[ConfigFile, ...], baked: set[str] | None = None) -> ServiceSpec:
    return ServiceSpec(
        name=service_name(project, robot, spec.service),
        robot=robot,
        component=spec.service,
        role=role,
        image=image,
        command=spec.entrypoint,
        args=spec.command,
        environment=spec.environment,
        mounts=_swarm_mounts(spec, baked or set()),
        configs=configs,
        constraints=constraints(project, robot, spec.host, arch),
        restart=RESTART_CONDITIONS.get(spec.restart, "any"),
        labels=((naming.LABEL_PROJECT, project), (LABEL_ROBOT, robot), (naming.LABEL_ROLE, role),
                (naming.LABEL_COMPONENT, spec.service)),
        limits=spec.limits,
    )


def robot_services(project: Project, robot: str, instance: Robot, release: Release) -> list[ServiceSpec]:
    """Every service of ``robot`` (an instance of the project's robot.yaml) at ``release``: its discovery servers,
    then its components, in file order. A KeyError names a component or arch the release has no image of."""
    here = replace(project, robot=instance)
    configs = dds_configs(project.name, robot, instance)
    services = []
    kind = discovery.for_robot(instance)
    for server in kind.servers():
        arch = instance.host(server.host).arch.value
        image = release.image(None, arch)
        if image is None:
            raise KeyError(f"base image for {arch}")
        services.append(_service(discovery_spec(here, server.index), project=project.name, robot=robot, arch=arch,
                                 image=image, role=naming.ROLE_DISCOVERY, configs=()))
    for component in instance.components:
        arch = instance.host(component.runs_on).arch.value
        baked = baked_targets(component)
        # the release's image first: for a component with its own image (robot.yaml ``image:``) too, it is that
        # image plus the read-only project files the service no longer mounts, by digest; the bare image only
        # when nothing is baked (a release record without the component), never with its files missing
        image = release.image(component.name, arch) or (component.image if not baked else None)
        if image is None:
            raise KeyError(f"{component.name} for {arch}")
        services.append(_service(component_spec(here, component), project=project.name, robot=robot, arch=arch,
                                 image=image, role=naming.ROLE_COMPONENT, configs=configs, baked=baked))
    return services


def release_labels(service: ServiceSpec, *, version: str, previous: str, previous_image: str,
                   changed: str, health: str) -> ServiceSpec:
    """``service`` with robocore's release labels: its target ``version`` (and image), the one before, when."""
    extra = ((LABEL_RELEASE, version), (LABEL_IMAGE, service.image), (LABEL_PREVIOUS, previous),
             (LABEL_PREVIOUS_IMAGE, previous_image), (LABEL_CHANGED, changed), (LABEL_HEALTH, health))
    keys = {key for key, _ in extra}
    return replace(service, labels=tuple((k, v) for k, v in service.labels if k not in keys) + extra)


def replace_label(service: ServiceSpec, key: str, value: str) -> ServiceSpec:
    """``service`` with label ``key`` set to ``value``."""
    return replace(service, labels=(*((k, v) for k, v in service.labels if k != key), (key, value)))


@dataclass(frozen=True)
class GateCheck:
    """What the health probe checks in a robot's graph (the fleet file's ``rollout.health``)."""

    nodes: tuple[str, ...]
    heard: tuple[str, ...]
    timeout: float


def probe_resource(instance: Robot) -> str:
    """The probe script (a resource name) that can read the graph of ``instance``: its discovery kind's; KeyError
    for a kind that has none."""
    return resource_for(instance, PROBE_RESOURCES, "a health probe")


def resource_for(instance: Robot, scripts: Mapping[str, str], what: str) -> str:
    """The script of ``scripts`` (discovery kind -> resource name) for ``instance``'s discovery kind; KeyError
    naming ``what`` and the kind when it has none."""
    kind = discovery.for_robot(instance).kind
    try:
        return scripts[kind]
    except KeyError:
        raise KeyError(f"{what} for discovery kind {kind}") from None


def probe_service(project: Project, robot: str, instance: Robot, release: Release, check: GateCheck,
                  script: str, suffix: str) -> ServiceSpec:
    """A one-shot service on the robot's first discovery server host (whose node has the base image) that runs the
    probe ``script`` as an observer of the robot's graph and prints its verdict as one JSON line."""
    kind = discovery.for_robot(instance)
    servers = kind.servers()
    host = instance.host(servers[0].host if servers else instance.components[0].runs_on)
    arch = host.arch.value
    image = release.image(None, arch)
    if image is None:
        raise KeyError(f"base image for {arch}")
    configs = dds_configs(project.name, robot, instance)
    digest = hashlib.sha256(script.encode()).hexdigest()[:12]
    script_config = ConfigFile(name=_config_name(project.name, robot, "probe", digest), target=PROBE_SCRIPT,
                               text=script)
    env = kind.observer_environment(host.name, files=in_folder(naming.CONTAINER_DDS))
    args = ["python3", PROBE_SCRIPT, "--timeout", f"{check.timeout:g}"]
    for node in check.nodes:
        args += ["--node", node]
    for topic in check.heard:
        args += ["--heard", topic]
    return ServiceSpec(
        name=service_name(project.name, robot, f"probe-{suffix}"),
        robot=robot,
        component="probe",
        role="probe",
        image=image,
        command=(naming.ENTRYPOINT,),
        args=tuple(args),
        environment=tuple(sorted(env.items())),
        mounts=(Mount("/dev/shm", "/dev/shm"),) if kind.transport.shared_memory else (),
        configs=(*configs, script_config),
        constraints=constraints(project.name, robot, host.name, arch),
        restart="none",
        labels=((naming.LABEL_PROJECT, project.name), (LABEL_ROBOT, robot), (LABEL_PROBE, "1")),
    )


def probe_verdict(output: str) -> dict[str, object] | None:
    """The probe's verdict: the last line of its output that is a JSON object and no progress line, else None."""
    for value in reversed(_json_lines(output)):
        if PROGRESS_KEY not in value:
            return value
    return None


#: The key of the probe's progress lines (``{"waiting": true, "missing": [...], "silent": [...]}``), printed every
#: few seconds while it waits: what it has not seen or heard yet.
PROGRESS_KEY = "waiting"


def probe_progress(output: str) -> dict[str, list[str]] | None:
    """The probe's last progress line (nodes ``missing`` and topics ``silent`` so far), None when it printed none."""
    for value in reversed(_json_lines(output)):
        if PROGRESS_KEY in value:
            lists = {key: value.get(key) for key in ("missing", "silent")}
            return {key: [str(item) for item in found] if isinstance(found, list) else []
                    for key, found in lists.items()}
    return None


def _json_lines(output: str) -> list[dict[str, object]]:
    """The JSON objects of ``output``, one a line (``docker service logs``' ``task@node |`` prefixes taken off)."""
    import json

    found = []
    for line in output.splitlines():
        text = line.strip()
        if "|" in text and not text.startswith("{"):
            text = text.split("|", 1)[1].strip()
        if text.startswith("{"):
            try:
                value = json.loads(text)
            except ValueError:
                continue
            if isinstance(value, dict):
                found.append(value)
    return found


def verdict_reason(verdict: dict[str, object]) -> str:
    """A failed probe verdict's reason in words: its error, the nodes missing, the topics not heard."""
    def listed(key: str) -> str:
        value = verdict.get(key)
        return ", ".join(str(item) for item in value) if isinstance(value, list) else ""

    missing, silent, error = listed("missing"), listed("silent"), str(verdict.get("error") or "")
    parts = ([error] if error else []) + ([f"nodes missing: {missing}"] if missing else []) \
        + ([f"not heard: {silent}"] if silent else [])
    return "; ".join(parts) or "unhealthy"


def robots_of(services: Sequence[ServiceSpec]) -> list[str]:
    """The robots of ``services``, in first-seen order."""
    return list(dict.fromkeys(s.robot for s in services))
