"""The dev container of ``robocore shell``: a pure description of mounts, environment and user.

The container starts as root and runs ``setup.sh`` (robocore/resources/shell, mounted
read-only at :data:`CONTAINER_SHELL`), which makes a user matching the developer and then
keeps the container alive. Every shell is a ``docker exec -u UID`` login bash into it; a
second ``shell`` on the same component joins the running container. Nothing here touches
Docker or the file system: the command layer gathers :class:`DevMachine` facts and executes.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path, PurePosixPath
from typing import Any

from robocore.config.model import Component, Robot
from robocore.plan import arches, naming
from robocore.plan.containers import Mount
from robocore.plan.gui import X11_SOCKETS
from robocore.project import Project

#: Where robocore's shell files (setup.sh, profile.sh, bashrc, colcon defaults) are mounted.
CONTAINER_SHELL = "/robocore/shell"
#: Where the per-container xauth cookie folder is mounted (XAUTHORITY points inside it).
CONTAINER_X11 = "/robocore/x11"
#: The XDG runtime folder holding the Wayland socket.
CONTAINER_XDG = "/robocore/xdg"
#: colcon's build and log folders, as ``robocore build`` uses them (robocore.plan.colcon).
CONTAINER_BUILD = "/robocore/build"
CONTAINER_LOG = "/robocore/log"
#: Mount points of the component's colcon folders (created on the dev machine before mounting).
BUILD_TARGETS = (CONTAINER_BUILD, naming.CONTAINER_INSTALL, CONTAINER_LOG)
XAUTH_FILE = "xauth"
SETUP_SCRIPT = "setup.sh"
SHELL_FILES = ("setup.sh", "profile.sh", "bashrc", "colcon-defaults.yaml")
ROLE = "shell"

_USER_RE = re.compile(r"^[a-z_][a-z0-9_-]{0,31}$")
_DEVICE_RULES = ("c *:* rmw", "b *:* rmw")


@dataclass(frozen=True)
class DevMachine:
    """Facts about the developer's machine and session that shape the dev container."""

    uid: int
    gid: int
    user: str | None = None  # $USER; sanitised by :func:`user_name`
    display: str | None = None  # $DISPLAY when an X server is usable
    x11_sockets: bool = False  # /tmp/.X11-unix exists
    xauth_cookie: bool = False  # a cookie for ``display`` was written to the per-container file
    wayland_socket: str | None = None  # host path of $XDG_RUNTIME_DIR/$WAYLAND_DISPLAY
    nvidia_runtime: bool = False  # `docker info` lists the nvidia runtime
    device_gids: tuple[int, ...] = ()  # groups of the passed device nodes on the host
    term: str | None = None


@dataclass(frozen=True)
class ShellRequest:
    """What the developer asked for on the command line."""

    component: str
    devices_all: bool = False
    gpus: bool | None = None  # None: when the NVIDIA runtime is present
    privileged: bool = False
    number: int = 0  # > 0 for ``--new`` containers


@dataclass(frozen=True)
class ShellSpec:
    """Everything about one dev container and the sessions exec'd into it."""

    name: str
    image: str
    component: str
    uid: int
    gid: int
    user: str
    home: str
    workdir: str
    mounts: tuple[Mount, ...]
    environment: Mapping[str, str]  # container environment (fixed at creation)
    session_env: Mapping[str, str]  # per ``docker exec`` (display, home, terminal)
    labels: Mapping[str, str]
    devices: tuple[str, ...] = ()
    device_cgroup_rules: tuple[str, ...] = ()
    gpus: bool = False
    privileged: bool = False
    network_mode: str = "host"
    ipc_mode: str = "host"
    platform: str = ""  # linux/<arch> of the component's host: the image is of that arch (emulated when foreign)
    entrypoint: tuple[str, ...] = ("/bin/sh", f"{CONTAINER_SHELL}/{SETUP_SCRIPT}")
    notes: tuple[str, ...] = field(default=(), compare=False)

    def container_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of docker-py ``containers.create`` (GPU requests added by the caller)."""
        kwargs: dict[str, Any] = {
            "image": self.image,
            "name": self.name,
            "entrypoint": list(self.entrypoint),
            "command": [],
            "user": "0:0",
            "working_dir": self.workdir,
            "environment": dict(self.environment),
            "labels": dict(self.labels),
            "mounts": [m.api() for m in self.mounts],
            "network_mode": self.network_mode,
            "ipc_mode": self.ipc_mode,
            "detach": True,
            "stdin_open": False,
            "tty": False,
            "init": False,
            "privileged": self.privileged,
        }
        if self.platform:
            kwargs["platform"] = self.platform
        if self.devices:
            kwargs["devices"] = list(self.devices)
        if self.device_cgroup_rules:
            kwargs["device_cgroup_rules"] = list(self.device_cgroup_rules)
        return kwargs

    def fingerprint(self) -> str:
        """Hash of what cannot change without a new container (not the per-session values)."""
        data = {
            "image": self.image,
            "uid": self.uid,
            "gid": self.gid,
            "user": self.user,
            "mounts": [m.api() for m in self.mounts],
            "environment": sorted(self.environment.items()),
            "devices": list(self.devices),
            "cgroup": list(self.device_cgroup_rules),
            "gpus": self.gpus,
            "privileged": self.privileged,
            "network": self.network_mode,
            "ipc": self.ipc_mode,
            "entrypoint": list(self.entrypoint),
            "platform": self.platform,
        }
        return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:16]


def user_name(raw: str | None, uid: int) -> str:
    """The user name inside the container: ``$USER`` when it is a valid name, else ``dev``."""
    if uid == 0:
        return "root"
    if raw and _USER_RE.match(raw) and raw != "root":
        return raw
    return "dev"


def image_for(robot: Robot, project_name: str, component: Component) -> str:
    """The component's ``image:``, else its staged image ``<prefix><component>:latest``."""
    if component.image:
        return component.image
    return f"{naming.component_image(robot, project_name, component.name)}:latest"


def workspace_dir(project: Project, component: Component) -> Path | None:
    """The component's workspace on the dev machine, or None for ``image:`` components."""
    if component.folder is None:
        return None
    return (project.root / component.folder).resolve()


def build_dirs(project: Project, component: str) -> dict[str, Path]:
    """colcon's folders on the dev machine, by their mount point in the container."""
    base = project.build_dir(component)
    return {
        CONTAINER_BUILD: base / "build",
        naming.CONTAINER_INSTALL: base / "install",
        CONTAINER_LOG: base / "log",
    }


def parse_device(spec: str) -> tuple[str, str, str]:
    """``host[:container[:perms]]`` -> (host, container, perms)."""
    parts = spec.split(":")
    host = parts[0]
    target = parts[1] if len(parts) > 1 and parts[1] else host
    perms = parts[2] if len(parts) > 2 and parts[2] else "rwm"
    return host, target, perms


def device_paths(component: Component, *, devices_all: bool) -> list[str]:
    """Host device paths the shell passes (their groups join the user's groups)."""
    if devices_all:
        return ["/dev"]
    return [parse_device(d)[0] for d in component.devices]


def volume_mounts(project: Project, component: Component) -> tuple[list[Mount], list[str]]:
    """The component's ``volumes`` as mounts (relative sources: in the project), and notes on bad ones."""
    mounts: list[Mount] = []
    notes: list[str] = []
    for volume in component.volumes:
        parts = volume.split(":")
        if len(parts) < 2:
            notes.append(f"volume {volume!r} of component {component.name} is not host:container; skipped")
            continue
        source = parts[0]
        host_path = Path(source) if source.startswith("/") else project.root / source
        read_only = len(parts) > 2 and parts[2] == "ro"
        mounts.append(Mount(str(host_path), parts[1], read_only))
    return mounts, notes


@dataclass
class _Part:
    """What one aspect of the dev container adds: mounts (in order), environment, session variables, notes."""

    mounts: list[Mount] = field(default_factory=list)
    env: dict[str, str] = field(default_factory=dict)
    session: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)


def _identity(project: Project, component: Component, name: str, user: str, home: str, machine: DevMachine,
              workspace: Path | None) -> _Part:
    """The shell files, the user's home, robocore's variables, and the component's workspace with its build
    folders when it has one (then colcon's defaults and log folder point into them)."""
    part = _Part(
        mounts=[Mount(str(project.shell_dir), CONTAINER_SHELL, read_only=True),
                Mount(str(project.home_dir(user)), home)],
        env={
            "ROBOCORE_PROJECT": project.name,
            "ROBOCORE_COMPONENT": component.name,
            "ROBOCORE_CONTAINER": name,
            "ROBOCORE_ROS_DISTRO": project.robot.ros_distro.value,
            "ROBOCORE_UID": str(machine.uid),
            "ROBOCORE_GID": str(machine.gid),
            "ROBOCORE_USER": user,
            "ROBOCORE_HOME": home,
        },
    )
    if workspace is not None:
        part.mounts.append(Mount(str(workspace), naming.CONTAINER_WS))
        part.mounts += [Mount(str(source), target) for target, source in build_dirs(project, component.name).items()]
        part.env["COLCON_DEFAULTS_FILE"] = f"{CONTAINER_SHELL}/colcon-defaults.yaml"
        part.env["COLCON_LOG_PATH"] = CONTAINER_LOG
    return part


def _discovery(project: Project, dds_env: Mapping[str, str] | None) -> _Part:
    """An observer (Fast DDS: a super client of the discovery servers) sees the whole graph; without the
    discovery kind's environment, DDS keeps its defaults apart from the domain id."""
    if dds_env is None:
        return _Part(env={"ROS_DOMAIN_ID": str(project.robot.ros_domain_id)})
    return _Part(mounts=[Mount(str(project.dds_dir), naming.CONTAINER_DDS, read_only=True)], env=dict(dds_env))


def _component_volumes(project: Project, component: Component, existing_paths: frozenset[str] | None) -> _Part:
    """The component's volumes, less those whose source is not on the dev machine (a note says so), and its
    environment."""
    volumes, notes = volume_mounts(project, component)
    part = _Part(env=dict(component.environment), notes=list(notes))
    for mount in volumes:
        if existing_paths is not None and mount.source not in existing_paths:
            part.notes.append(f"volume {mount.source} of component {component.name} does not exist here; skipped")
            continue
        part.mounts.append(mount)
    return part


def _gui(project: Project, machine: DevMachine, name: str, home: str, user: str) -> _Part:
    """X11 through a per-container cookie, the Wayland socket when there is one; and the session's terminal."""
    part = _Part(session={"HOME": home, "USER": user})
    if machine.term:
        part.session["TERM"] = machine.term
    if machine.display:
        if machine.x11_sockets:
            part.mounts.append(Mount(X11_SOCKETS, X11_SOCKETS, read_only=True))
        part.mounts.append(Mount(str(project.x11_dir(name)), CONTAINER_X11, read_only=True))
        part.env["QT_X11_NO_MITSHM"] = "1"
        part.session["DISPLAY"] = machine.display
        part.session["XAUTHORITY"] = f"{CONTAINER_X11}/{XAUTH_FILE}"
    if machine.wayland_socket:
        socket_name = PurePosixPath(machine.wayland_socket).name
        part.mounts.append(Mount(machine.wayland_socket, f"{CONTAINER_XDG}/{socket_name}"))
        part.env["ROBOCORE_XDG_RUNTIME_DIR"] = CONTAINER_XDG
        part.session["XDG_RUNTIME_DIR"] = CONTAINER_XDG
        part.session["WAYLAND_DISPLAY"] = socket_name
    return part


@dataclass
class _Hardware(_Part):
    """Devices, GPUs and privileges: a :class:`_Part`, plus the device options of the container."""

    devices: tuple[str, ...] = ()
    rules: tuple[str, ...] = ()
    gpus: bool = False


def _hardware(component: Component, request: ShellRequest, machine: DevMachine) -> _Hardware:
    """All of ``/dev`` (``--devices-all``) or the component's devices, the device nodes' groups, the GPUs
    (``--gpus``, else when Docker has the NVIDIA runtime), and notes on what the robot gives the component and
    this shell does not. The NVIDIA variables are defaults: the component's own values win."""
    part = _Hardware()
    if request.devices_all:
        part.mounts.append(Mount("/dev", "/dev"))
        part.rules = _DEVICE_RULES
    else:
        part.devices = tuple(component.devices)
    if machine.device_gids:
        part.env["ROBOCORE_EXTRA_GIDS"] = " ".join(str(g) for g in sorted(set(machine.device_gids)))
    part.gpus = machine.nvidia_runtime if request.gpus is None else request.gpus
    if not part.gpus and component.nvidia and request.gpus is None:
        part.notes.append(f"component {component.name} asks for nvidia but Docker has no NVIDIA runtime: no GPU")
    if component.privileged and not request.privileged:
        part.notes.append(f"component {component.name} runs privileged on the robot; add --privileged for the same "
                          "here")
    return part


def plan_shell(
    project: Project,
    request: ShellRequest,
    machine: DevMachine,
    *,
    dds_env: Mapping[str, str] | None = None,
    existing_paths: frozenset[str] | None = None,
) -> ShellSpec:
    """The dev container of ``request.component`` for the developer described by ``machine``.

    ``dds_env`` is the observer environment of the robot's discovery kind (:mod:`robocore.plan.discovery`);
    None leaves DDS at its defaults apart from the domain id. ``existing_paths``, when given, is the set of
    component volume sources that exist on the dev machine; the others are skipped with a note.
    """
    component = project.component(request.component)
    name = naming.shell_container_name(project.name, component.name, request.number)
    user = user_name(machine.user, machine.uid)
    home = f"/home/{user}"
    workspace = workspace_dir(project, component)
    hardware = _hardware(component, request, machine)
    parts = [_identity(project, component, name, user, home, machine, workspace), _discovery(project, dds_env),
             _component_volumes(project, component, existing_paths), _gui(project, machine, name, home, user),
             hardware]
    env: dict[str, str] = {}
    for part in parts:  # later parts win: the component's environment over discovery's, robocore's GUI over both
        env.update(part.env)
    if hardware.gpus:
        env.setdefault("NVIDIA_VISIBLE_DEVICES", "all")
        env.setdefault("NVIDIA_DRIVER_CAPABILITIES", "all")
    spec = ShellSpec(
        name=name,
        image=image_for(project.robot, project.name, component),
        component=component.name,
        uid=machine.uid,
        gid=machine.gid,
        user=user,
        home=home,
        workdir=naming.CONTAINER_WS if workspace is not None else home,
        mounts=tuple(mount for part in parts for mount in part.mounts),
        environment=env,
        session_env={key: value for part in parts for key, value in part.session.items()},
        labels={},
        devices=hardware.devices,
        device_cgroup_rules=hardware.rules,
        gpus=hardware.gpus,
        privileged=request.privileged,
        platform=arches.platform(project.robot.host(component.runs_on).arch.value),
        notes=tuple(note for part in parts for note in part.notes),
    )
    labels = {
        naming.LABEL_PROJECT: project.name,
        naming.LABEL_COMPONENT: component.name,
        naming.LABEL_ROLE: ROLE,
        naming.LABEL_SPEC: spec.fingerprint(),
    }
    return replace(spec, labels=labels)


def exec_argv(spec: ShellSpec, *, cmd: str | None, stdin_tty: bool, stdout_tty: bool = False,
              docker: str = "docker") -> list[str]:
    """``docker exec`` of a login bash (``cmd`` None) or of ``bash -lc CMD``.

    ``CMD`` gets a TTY when robocore has one (stdin and stdout both terminals), so that ``tmux``,
    ``htop`` or an editor work; with its output piped or redirected it gets none, and its output
    keeps plain line ends. The user is the numeric UID, so Docker applies the user's primary and
    supplementary groups from the container's /etc/passwd and /etc/group (``-u UID:GID`` would
    drop them).
    """
    argv = [docker, "exec"]
    if cmd is None:
        argv.append("-it" if stdin_tty else "-i")
    elif stdin_tty and stdout_tty:
        argv.append("-it")
    elif not stdin_tty:
        argv.append("-i")
    argv += ["-u", str(spec.uid), "-w", spec.workdir]
    for key, value in spec.session_env.items():
        argv += ["-e", f"{key}={value}"]  # KEY=...: never an option
    argv += ["--", spec.name]
    argv += ["bash", "-l"] if cmd is None else ["bash", "-lc", cmd]
    return argv


def describe(spec: ShellSpec) -> dict[str, Any]:
    """A JSON-friendly view of the spec, for ``--dry-run``."""
    return {
        "container": spec.name,
        "image": spec.image,
        "user": f"{spec.user} ({spec.uid}:{spec.gid})",
        "home": spec.home,
        "workdir": spec.workdir,
        "network": spec.network_mode,
        "ipc": spec.ipc_mode,
        "mounts": [f"{m.source}:{m.target}{':ro' if m.read_only else ''}" for m in spec.mounts],
        "environment": dict(spec.environment),
        "session": dict(spec.session_env),
        "devices": list(spec.devices),
        "device_cgroup_rules": list(spec.device_cgroup_rules),
        "gpus": spec.gpus,
        "privileged": spec.privileged,
        "labels": dict(spec.labels),
        "notes": list(spec.notes),
    }
