"""Container specs: what each deployed container is, as data.

One :class:`ContainerSpec` per component and per discovery server (what the robot's discovery
kind, :mod:`robocore.plan.discovery`, says they run), built by pure functions from the project.
The same spec renders to docker-py ``containers.create`` keyword arguments (what ``run`` does)
and to a compose service (what ``.robocore/compose/<host>.yaml`` holds), so the two can never
disagree. The spec's hash is stored as a label; ``run`` recreates a container only when that
hash (or the image behind the tag) changed.
"""

from __future__ import annotations

import hashlib
import json
import shlex
from dataclasses import dataclass, field, fields
from pathlib import PurePosixPath
from typing import Any

from robocore.config.model import Component, Host, Robot, is_project_path, port_pattern, read_only_project_path
from robocore.plan import arches, discovery, gui, layout, naming, resources
from robocore.plan.addresses import extra_hosts, reachable_from_container
from robocore.plan.layout import component_root, host_paths
from robocore.plan.resources import Limits
from robocore.project import Project

DEFAULT_TAG = "latest"
#: Command of a component that has no entrypoint: stay up so that ``connect`` can enter it.
IDLE_COMMAND = ("sleep", "infinity")


@dataclass(frozen=True)
class Mount:
    """A bind mount (absolute ``source``) or a named volume (bare ``source``)."""

    source: str
    target: str
    read_only: bool = False

    @property
    def is_named_volume(self) -> bool:
        """True for a named volume (``logs:/logs``), False for a bind mount of a host path."""
        return not self.source.startswith("/")

    @property
    def text(self) -> str:
        """``source:target[:ro]``: docker-py's and compose's short form."""
        return f"{self.source}:{self.target}" + (":ro" if self.read_only else "")

    def api(self) -> dict[str, Any]:
        """The Docker Engine API form (a ``HostConfig.Mounts`` entry)."""
        return {"Type": "volume" if self.is_named_volume else "bind", "Source": self.source, "Target": self.target,
                "ReadOnly": self.read_only}


@dataclass(frozen=True)
class ContainerSpec:
    """Everything ``run`` needs to create one container, and nothing host-specific beyond it."""

    name: str  # container name
    service: str  # compose service name
    host: str
    role: str  # naming.ROLE_COMPONENT | naming.ROLE_DISCOVERY
    project: str
    image: str  # repository:tag
    entrypoint: tuple[str, ...] | None  # None: the image's own
    command: tuple[str, ...] | None  # None: the image's own
    environment: tuple[tuple[str, str], ...]  # sorted by name
    network_mode: str  # host | bridge
    ipc_mode: str | None = None  # "host" when same-host containers share memory (discovery.Transport)
    ports: tuple[str, ...] = ()  # only on bridge
    devices: tuple[str, ...] = ()
    mounts: tuple[Mount, ...] = ()
    gpus: bool = False
    privileged: bool = False
    restart: str = "unless-stopped"
    depends_on: tuple[str, ...] = ()  # services started first (same host)
    extra_labels: tuple[tuple[str, str], ...] = field(default=())
    extra_hosts: tuple[tuple[str, str], ...] = ()  # (name, address or "host-gateway") in /etc/hosts
    limits: Limits | None = None  # robot.yaml's resources (plan/resources.py)

    @property
    def env(self) -> dict[str, str]:
        """The environment as a dict."""
        return dict(self.environment)

    @property
    def spec_hash(self) -> str:
        """A short content hash of the spec: equal hashes mean nothing to recreate."""
        # what dataclasses.asdict gives (the hashes of running containers depend on it), without its deep copies:
        # 10,000 specs are hashed for one compose file of 10,000 services
        data = {name: getattr(self, name) for name in _SPEC_FIELDS}
        data["mounts"] = [{name: getattr(m, name) for name in _MOUNT_FIELDS} for m in self.mounts]
        if not data["extra_hosts"]:  # absent, as before the field existed: unchanged specs keep their hash
            del data["extra_hosts"]
        if self.limits is None:
            del data["limits"]
        else:
            data["limits"] = self.limits.as_dict()
        payload = json.dumps(data, sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(payload.encode()).hexdigest()[:16]

    @property
    def labels(self) -> dict[str, str]:
        """The container's labels, the spec hash included."""
        labels = {
            naming.LABEL_PROJECT: self.project,
            naming.LABEL_COMPONENT: self.service,
            naming.LABEL_ROLE: self.role,
            naming.LABEL_SPEC: self.spec_hash,
        }
        labels.update(self.extra_labels)
        return labels

    def docker_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of docker-py's ``client.containers.create(**kwargs)``."""
        kwargs: dict[str, Any] = {
            "image": self.image,
            "name": self.name,
            "detach": True,
            "environment": self.env,
            "labels": self.labels,
            "network_mode": self.network_mode,
            "restart_policy": {"Name": "" if self.restart == "no" else self.restart},
            "privileged": self.privileged,
            "init": self.role in naming.MANAGED_ROLES,  # SIGTERM reaches a process without a handler of its own
        }
        if self.entrypoint is not None:
            kwargs["entrypoint"] = list(self.entrypoint)
        if self.command is not None:
            kwargs["command"] = list(self.command)
        if self.ipc_mode:
            kwargs["ipc_mode"] = self.ipc_mode
        if self.mounts:
            from docker.types import Mount as DockerMount

            # Typed mounts: a missing bind source is an error, not a silently created empty folder.
            kwargs["mounts"] = [
                DockerMount(m.target, m.source, type="volume" if m.is_named_volume else "bind", read_only=m.read_only)
                for m in self.mounts
            ]
        if self.devices:
            kwargs["devices"] = list(self.devices)
        if self.ports:
            kwargs["ports"] = docker_ports(self.ports)
        if self.extra_hosts:
            kwargs["extra_hosts"] = dict(self.extra_hosts)
        if self.limits is not None:
            kwargs.update(resources.docker_kwargs(self.limits))
        if self.gpus:
            from docker.types import DeviceRequest

            kwargs["device_requests"] = [DeviceRequest(driver="nvidia", count=-1, capabilities=[["gpu"]])]
        return kwargs

    def compose_service(self) -> dict[str, Any]:
        """The compose-file service of this spec (compose specification, plain YAML types).

        Compose substitutes ``$VAR`` in every value; each ``$`` is written ``$$`` so that the
        container gets exactly what ``run`` gives it.
        """
        service: dict[str, Any] = {"image": self.image, "container_name": self.name}
        if self.entrypoint is not None:
            service["entrypoint"] = [compose_escape(a) for a in self.entrypoint]
        if self.command is not None:
            service["command"] = [compose_escape(a) for a in self.command]
        service["network_mode"] = self.network_mode
        if self.ipc_mode:
            service["ipc"] = self.ipc_mode
        if self.role in naming.MANAGED_ROLES:
            service["init"] = True
        if self.depends_on:
            service["depends_on"] = list(self.depends_on)
        service["environment"] = {k: compose_escape(v) for k, v in self.env.items()}
        if self.mounts:
            service["volumes"] = [compose_escape(m.text) for m in self.mounts]
        if self.devices:
            service["devices"] = list(self.devices)
        if self.ports:
            service["ports"] = list(self.ports)
        if self.extra_hosts:
            service["extra_hosts"] = [f"{name}:{address}" for name, address in self.extra_hosts]
        if self.privileged:
            service["privileged"] = True
        if self.gpus:
            service["deploy"] = {
                "resources": {
                    "reservations": {"devices": [{"driver": "nvidia", "count": "all", "capabilities": ["gpu"]}]}
                }
            }
        if self.limits is not None:
            service.update(resources.compose_keys(self.limits))
        service["restart"] = self.restart
        service["labels"] = self.labels
        return service


_SPEC_FIELDS = tuple(f.name for f in fields(ContainerSpec))
_MOUNT_FIELDS = tuple(f.name for f in fields(Mount))


def compose_escape(text: str) -> str:
    """``text`` with every ``$`` doubled: compose's escape for a literal dollar sign."""
    return text.replace("$", "$$")


def docker_ports(ports: tuple[str, ...]) -> dict[str, Any]:
    """docker-py's ``ports`` mapping (``"8080/tcp": ("0.0.0.0", 80)``) from ``[ip:]host:container[/proto]``.

    Ranges (``8000-8002:9000-9002``) expand to one entry per port.
    """
    out: dict[str, Any] = {}
    pattern = port_pattern()
    for text in ports:
        match = pattern.match(text)
        if match is None:
            raise ValueError(f"invalid port mapping {text!r}")
        host_start = int(match["host"])
        host_end = int(match["host_end"] or host_start)
        cont_start = int(match["cont"])
        cont_end = int(match["cont_end"] or cont_start)
        if host_end - host_start != cont_end - cont_start:
            raise ValueError(f"port ranges of different lengths in {text!r}")
        proto = match["proto"] or "tcp"
        ip = match["ip"].strip("[]") if match["ip"] else None
        for offset in range(cont_end - cont_start + 1):
            binding: Any = (ip, host_start + offset) if ip else host_start + offset
            out[f"{cont_start + offset}/{proto}"] = binding
    return out


def image_ref(project: Project, repository: str, tag: str | None) -> str:
    """``repository:tag``; a released ``tag`` is taken from the robot's registry."""
    if tag is None:
        return f"{repository}:{DEFAULT_TAG}"
    return f"{naming.registry_image(project.robot, repository)}:{tag}"


def base_ref(project: Project, arch: str, tag: str | None) -> str:
    """The base image a container of a host of ``arch`` runs (a discovery server, a test run's host):
    ``<base>:latest`` when that is the arch of the machine robocore runs on, else ``<base>:latest-<arch>``,
    the names prepare-base gives them; a released ``tag`` is one multi-arch name, which each host pulls for
    its own arch."""
    repository = naming.base_image(project.robot, project.name)
    if tag is not None:
        return image_ref(project, repository, tag)
    return f"{repository}:{arches.base_tag(arch, project.native_arch)}"


def component_command(component: Component) -> tuple[str, ...] | None:
    """argv of a component: its entrypoint then launch_args, split like a shell would (no shell).

    Without an entrypoint, a workspace component idles (so it can be entered) and an
    ``image:`` component runs its image's own command.
    """
    if component.entrypoint:
        return tuple(shlex.split(component.entrypoint) + shlex.split(component.launch_args or ""))
    return None if component.image else IDLE_COMMAND


def _user_mount(text: str, base: PurePosixPath, *, remote: bool = False) -> Mount:
    """A robot.yaml volume ``source:target[:ro|rw]``; relative sources are taken from ``base``.

    On a remote host (``base`` is ``<mount_root>/<component>``) a read-only project path comes
    with each synced release (``current/files/<path>``); a writable one is a folder of that
    host that robocore never overwrites.
    """
    parts = text.split(":")
    source, target = parts[0], parts[1] if len(parts) > 1 else parts[0]
    read_only = len(parts) > 2 and parts[2] == "ro"
    synced = read_only_project_path(text) if remote else None
    if synced is not None:
        source = str(base / layout.CURRENT / layout.FILES / synced)
    elif is_project_path(source):
        source = str(base / source)
    return Mount(source=source, target=target, read_only=read_only)


def seen_from(robot: Robot, network_mode: str) -> Robot:
    """``robot`` with each host at the address a container on ``network_mode`` reaches it by.

    On a bridge network a container's loopback is its own, so a host at a loopback address (the
    dev machine) is reached through the bridge's gateway; every discovery kind then hands out
    addresses the container can use."""
    hosts = [h.model_copy(update={"ip": reachable_from_container(h.ip, network_mode), "docker": h.access})
             for h in robot.hosts]
    if all(new.ip == old.ip for new, old in zip(hosts, robot.hosts, strict=True)):
        return robot
    return robot.model_copy(update={"hosts": hosts})


@dataclass(frozen=True)
class _ClientSide:
    """What the robot's discovery kind gives every component of one host on one network mode: the same for all of
    them, so a host's specs compute it once per network mode (10,000 components: 10,000 robot copies otherwise)."""

    environment: tuple[tuple[str, str], ...]
    ipc_mode: str | None
    depends_on: tuple[str, ...]


def _client_side(robot: Robot, host: str, network: str) -> _ClientSide:
    kind = discovery.for_robot(seen_from(robot, network))
    return _ClientSide(environment=tuple(kind.client_environment(host, network_mode=network).items()),
                       ipc_mode=kind.transport.ipc_mode(network),
                       depends_on=tuple(discovery_service(s.index) for s in kind.servers_on(host)))


def component_spec(project: Project, component: Component, *, tag: str | None = None) -> ContainerSpec:
    """The container of ``component`` on its host."""
    return _component_spec(project, component, tag, {})


def _component_spec(project: Project, component: Component, tag: str | None,
                    client_sides: dict[tuple[str, str], _ClientSide]) -> ContainerSpec:
    """:func:`component_spec`, with the client sides computed so far (host, network mode -> client side)."""
    robot = project.robot
    host: Host = robot.host(component.runs_on)
    paths = host_paths(project, host, component.name)
    network = component.network_mode
    client = client_sides.get((host.name, network))
    if client is None:
        client = client_sides[host.name, network] = _client_side(robot, host.name, network)
    env = dict(client.environment)
    mounts: list[Mount] = []
    if component.has_workspace:
        mounts.append(Mount(paths.install, naming.CONTAINER_INSTALL, read_only=True))
    mounts.append(Mount(paths.dds, naming.CONTAINER_DDS, read_only=True))
    display = gui.gui_plan(project, component)
    env.update(display.environment)
    mounts.extend(Mount(b.source, b.target, read_only=b.read_only) for b in display.binds)
    if component.volumes:
        base = PurePosixPath(str(project.root)) if host.is_local else component_root(host, component.name)
        mounts.extend(_user_mount(v, base, remote=not host.is_local) for v in component.volumes)
    env.update(component.environment)
    if component.image:
        image = component.image
        entrypoint = None
    else:
        image = image_ref(project, naming.component_image(robot, project.name, component.name), tag)
        entrypoint = (naming.ENTRYPOINT,)
    return ContainerSpec(
        name=naming.container_name(project.name, component.name),
        service=component.name,
        host=host.name,
        role=naming.ROLE_COMPONENT,
        project=project.name,
        image=image,
        entrypoint=entrypoint,
        command=display.command or component_command(component),
        environment=tuple(sorted(env.items())),
        network_mode=network,
        ipc_mode=client.ipc_mode,
        ports=tuple(component.ports) if network == "bridge" else (),
        devices=tuple(component.devices),
        mounts=tuple(mounts),
        gpus=component.nvidia,
        privileged=component.privileged,
        limits=Limits.of(component.resources),
        restart=component.restart,
        depends_on=client.depends_on + display.depends_on,
        extra_hosts=extra_hosts(network),
    )


def discovery_service(index: int) -> str:
    """The compose service name of discovery server ``index``."""
    return f"discovery-{index}"


def discovery_state_volume(project_name: str, index: int) -> str:
    """The named volume that keeps discovery server ``index``'s state across restarts (a full ``down`` removes it)."""
    return f"{project_name}-discovery-{index}-state"


def discovery_spec(project: Project, index: int, *, tag: str | None = None) -> ContainerSpec:
    """The container of discovery server ``index``: the base image of its host's arch running what the robot's
    discovery kind says."""
    robot = project.robot
    kind = discovery.for_robot(robot)
    endpoint = kind.servers()[index]
    process = kind.server_process(index)
    mounts: tuple[Mount, ...] = ()
    if process.state_dir is not None:
        mounts = (Mount(discovery_state_volume(project.name, index), process.state_dir),)
    return ContainerSpec(
        name=naming.discovery_container_name(project.name, index),
        service=discovery_service(index),
        host=endpoint.host,
        role=naming.ROLE_DISCOVERY,
        project=project.name,
        image=base_ref(project, robot.host(endpoint.host).arch.value, tag),
        entrypoint=(naming.ENTRYPOINT,),
        command=process.command,
        environment=tuple(sorted(process.environment.items())),
        network_mode="host",
        ipc_mode=kind.transport.ipc_mode("host"),
        mounts=mounts,
        restart="unless-stopped",
    )


def state_volumes(project: Project, host: str) -> list[str]:
    """The named volumes of the discovery servers on ``host``: what a full ``down`` removes, so that the next
    start is a first start."""
    specs = [discovery_spec(project, s.index) for s in discovery.for_robot(project.robot).servers_on(host)]
    return [m.source for spec in specs for m in spec.mounts if m.is_named_volume]


def host_specs(project: Project, host: str, *, tag: str | None = None) -> list[ContainerSpec]:
    """Every container of ``host``: its discovery servers first, then its components in file order."""
    robot = project.robot
    specs = [discovery_spec(project, s.index, tag=tag) for s in discovery.for_robot(robot).servers_on(host)]
    client_sides: dict[tuple[str, str], _ClientSide] = {}
    specs += [_component_spec(project, c, tag, client_sides) for c in robot.components_on(host)]
    return specs
