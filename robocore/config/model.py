"""The robot.yaml model: frozen pydantic models, unknown keys rejected.

Field-level rules live here; rules that look across fields or at the file system
live in :mod:`robocore.config.checks` so that every problem carries its own key path.
"""

from __future__ import annotations

import ipaddress
from enum import Enum
from typing import Any, Literal

from pydantic import ConfigDict, Field, field_validator

from robocore.config.desktop import Desktop
from robocore.config.mappings import is_project_path as is_project_path
from robocore.config.mappings import port_pattern as port_pattern
from robocore.config.mappings import read_only_project_path as read_only_project_path
from robocore.config.resources import Resources
from robocore.config.sources import (
    ALLOW_PROTOCOL_HELP,
    CheckoutFolder,
    GitOptIn,
    GitRef,
    GitUrl,
    default_folder,
    git_protocol,
    url_rules,
)
from robocore.config.strict import Strict as Strict
from robocore.config.values import (
    ENV_NAME,
    MULTI_LINE,
    AptPackage,
    EnvName,
    HostAddress,
    ImagePrefix,
    ImageRef,
    MountRoot,
    MultiLine,
    Name,
    Number,
    OneLine,
    PipRequirement,
    Registry,
    ShellWords,
    UserName,
    schema_pattern,
    shown,
)

#: ROS 2 distributions robocore knows, with the Fast DDS line each ship; ROS 1 ones (every other distro is ROS 2).
FASTDDS_LINE: dict[str, int] = {"humble": 2, "jazzy": 2, "kilted": 3, "rolling": 3}
ROS1_DISTROS = frozenset({"melodic", "noetic"})


class RosDistro(str, Enum):
    """ROS distributions robocore can target: ROS 1 (melodic, noetic) and ROS 2."""

    melodic = "melodic"
    noetic = "noetic"
    humble = "humble"
    jazzy = "jazzy"
    kilted = "kilted"
    rolling = "rolling"


class Arch(str, Enum):
    """CPU architectures of hosts (Docker platform names)."""

    amd64 = "amd64"
    arm64 = "arm64"


#: Each architecture's name as the kernel says it (``uname -m``, ``platform.machine()``, qemu's binaries).
MACHINE_NAMES = {Arch.amd64.value: "x86_64", Arch.arm64.value: "aarch64"}


def docker_arch(machine: str) -> str:
    """A ``platform.machine()`` name in Docker terms (amd64, arm64); unknown names come back lower-cased."""
    machine = machine.lower()
    return next((arch for arch, name in MACHINE_NAMES.items() if machine in (arch, name)), machine)


def kernel_arch(arch: str) -> str:
    """A Docker arch name as the kernel says it (``arm64`` -> ``aarch64``); unknown names come back unchanged."""
    return MACHINE_NAMES.get(arch, arch)


class DockerAccess(str, Enum):
    """How robocore reaches a host's Docker daemon."""

    local = "local"
    ssh = "ssh"
    tls = "tls"
    tcp = "tcp"


class TlsFiles(Strict):
    """Client certificate files for a Docker daemon served over TLS."""

    ca_cert: OneLine = Field(description="CA certificate that signed the daemon's certificate.")
    client_cert: OneLine = Field(description="Client certificate.")
    client_key: OneLine = Field(description="Client private key (kept on the dev machine, never copied).")


class Host(Strict):
    """A machine of the robot (or the dev machine) that runs components."""

    name: Name
    ip: HostAddress
    user: UserName = Field(default="root", description="SSH user.")
    arch: Arch = Arch.amd64
    docker: DockerAccess | None = Field(
        default=None,
        description="How the Docker daemon is reached: local (this machine's socket), ssh "
        "(default for remote hosts), tls (TCP with client certificates), tcp (plain, needs insecure: true).",
    )
    docker_port: Number | None = Field(
        default=None, ge=1, le=65535, description="TCP port of the daemon (tls: 2376, tcp: 2375)."
    )
    ssh_port: Number = Field(default=22, ge=1, le=65535)
    tls: TlsFiles | None = None
    insecure: bool = Field(default=False, description="Allow plain unauthenticated TCP to this host's daemon.")
    mount_root: MountRoot | None = None
    builds_here: bool = Field(default=False, description="Build this host's components natively on the host itself.")

    @property
    def is_local(self) -> bool:
        """True when the host is this machine."""
        return self.access is DockerAccess.local

    @property
    def access(self) -> DockerAccess:
        """The effective Docker access: explicit, else local for loopback addresses, else ssh."""
        if self.docker is not None:
            return self.docker
        if self.ip in {"127.0.0.1", "localhost", "::1"}:
            return DockerAccess.local
        return DockerAccess.ssh

    @property
    def is_loopback(self) -> bool:
        """True when ``ip`` is a loopback address (127.0.0.0/8, ::1 or localhost): unreachable from other hosts."""
        return is_loopback_address(self.ip)

    @property
    def deploy_root(self) -> str:
        """The folder on the host that receives synced trees."""
        if self.mount_root:
            return self.mount_root.rstrip("/") or "/"
        return "/root/robocore" if self.user == "root" else f"/home/{self.user}/robocore"


class CommonPackage(Strict):
    """A ROS package shared by every component, built into the base image."""

    model_config = ConfigDict(json_schema_extra=lambda schema: url_rules(schema, "repo"))

    name: Name
    folder: OneLine | None = Field(default=None, description="Local folder of the package (inside the project).")
    repo: GitUrl | None = Field(default=None, description="Git URL, fetched on the dev machine.")
    branch: GitRef | None = Field(default=None, description="Branch, tag or commit of repo.")
    allow_protocol: GitOptIn | None = Field(default=None, description=ALLOW_PROTOCOL_HELP)

    @property
    def repo_protocol(self) -> str | None:
        """The protocol git uses for ``repo`` (https, ssh, or an allowed one), None without a repo."""
        return git_protocol(self.repo) if self.repo else None


class Repository(Strict):
    """A source dependency in vcstool's .repos terms."""

    model_config = ConfigDict(json_schema_extra=lambda schema: url_rules(schema, "url"))

    url: GitUrl
    version: GitRef | None = None
    folder: CheckoutFolder | None = None
    type: Literal["git"] = "git"
    allow_protocol: GitOptIn | None = Field(default=None, description=ALLOW_PROTOCOL_HELP)

    @property
    def protocol(self) -> str:
        """The protocol git uses for ``url`` (https, ssh, or the allowed one)."""
        return git_protocol(self.url)

    @property
    def checkout_folder(self) -> str:
        """The folder under the deps source tree: ``folder``, else the URL's last segment without ``.git``."""
        return self.folder or default_folder(self.url)


class BaseKind(str, Enum):
    """Where the ROS installation of the base image comes from."""

    official = "official"
    wheels = "wheels"
    debian = "debian"


class BaseImage(Strict):
    """The base image every component image starts from."""

    kind: BaseKind = Field(
        default=BaseKind.official,
        description="official: ros:<distro>-ros-base; wheels: Debian 12 + ROS 2 from PyPI; "
        "debian: Debian 12's own ROS 1 packages (noetic).",
    )
    image: ImageRef | None = Field(
        default=None, description="Override of the FROM image (official) or of the root image (wheels, debian)."
    )


#: Each discovery kind's default port.
DEFAULT_PORTS: dict[str, int] = {"fastdds": 11811, "rosmaster": 11311}


class DiscoveryServer(Strict):
    """One discovery server (fastdds: a Fast DDS discovery server; rosmaster: the ROS master)."""

    host: Name
    port: Number | None = Field(
        default=None, ge=1024, le=65535, description="Default: 11811 (fastdds), 11311 (rosmaster)."
    )


class Discovery(Strict):
    """How nodes find each other."""

    kind: Literal["fastdds", "rosmaster"] | None = Field(
        default=None,
        description="fastdds (ROS 2's default): Fast DDS discovery servers, every node a client of all of them; "
        "rosmaster (ROS 1's default): one ROS master (roscore).",
    )
    servers: list[DiscoveryServer] = Field(
        default_factory=list, description="Default: one server on the first host."
    )
    transport: Literal["shm", "udp"] = Field(
        default="shm",
        description="shm: shared memory between containers of one host (ipc: host); udp: UDP only.",
    )


class Component(Strict):
    """A group of ROS nodes with its dependencies, run as one container on one host."""

    name: Name
    runs_on: Name
    folder: OneLine | None = Field(
        default=None, description="The component's ROS workspace (packages under it, or under its src/)."
    )
    image: ImageRef | None = Field(
        default=None, description="A pre-built image; excludes folder, apt_packages and repositories."
    )
    apt_packages: list[AptPackage] = Field(
        default_factory=list, description="Debian packages (name, name=version or name/release)."
    )
    pip_packages: list[PipRequirement] = Field(default_factory=list, description="pip requirements (PEP 508).")
    repositories: list[Repository] = Field(default_factory=list)
    postinstall: list[MultiLine] = Field(
        default_factory=list, description="Shell commands run in the image after dependencies are installed."
    )
    entrypoint: ShellWords | None = Field(default=None, description="Command run at container start, ROS sourced.")
    launch_args: ShellWords | None = Field(default=None, description="Arguments appended to entrypoint.")
    devices: list[OneLine] = Field(
        default_factory=list, description="/dev/host_path[:container_path[:permissions]]; block devices (disks) "
        "and all of /dev are allowed, and validate warns."
    )
    ports: list[OneLine] = Field(
        default_factory=list, description="[ip:]host:container[/proto]; only used off host networking."
    )
    environment: dict[EnvName, MultiLine] = Field(
        default_factory=dict,
        description="Environment variables of the container (POSIX names); numbers and booleans are written as "
        "text; values may span lines but hold no other control characters.",
        json_schema_extra=lambda schema: _environment_schema(schema),
    )
    volumes: list[OneLine] = Field(
        default_factory=list, description="host_path:container_path[:ro|rw]. Mounting / or the Docker socket "
        "is allowed, and validate warns."
    )
    allow_outside_project: bool = Field(
        default=False,
        description="Let read-only project volumes (./path:/x:ro) lead outside the project through a symlink; "
        "sync then copies what they point to onto the host (validate warns).",
    )
    network: Literal["host", "bridge"] | None = Field(
        default=None,
        description="host (default; DDS across hosts needs it) or bridge "
        "(default when ports are given, which host networking ignores).",
    )
    restart: Literal["no", "always", "unless-stopped", "on-failure"] = "unless-stopped"
    nvidia: bool = False
    gui: bool | Name = Field(
        default=False, description="Show windows: true on the host's own display (:0), or the name of a "
        "desktop component on the same host to draw into its VNC desktop.",
    )
    desktop: Desktop | None = Field(
        default=None, description="Serve a VNC desktop (Xvnc, noVNC) that gui components of this host draw into.",
    )
    privileged: bool = Field(default=False, description="Full access to the host's devices and kernel "
                             "(validate warns).")
    resources: Resources | None = Field(default=None, description="CPU and memory: requests (guaranteed), limits "
                                        "(at most), priority (critical: killed last when memory runs out).")

    @field_validator("gui", mode="before")
    @classmethod
    def _gui_kind(cls, value: object) -> object:
        if not isinstance(value, (bool, str)):
            raise ValueError(f"must be true, false or the name of a desktop component (got {shown(value)})")
        return value

    @field_validator("environment", mode="before")
    @classmethod
    def _stringify_env(cls, value: object) -> object:
        if isinstance(value, dict):
            return {k: (v if isinstance(v, str) else _scalar_text(v)) for k, v in value.items()}
        return value

    @property
    def network_mode(self) -> str:
        """The effective network: explicit, else bridge when ports are published, else host."""
        if self.network is not None:
            return self.network
        return "bridge" if self.ports else "host"

    @property
    def has_workspace(self) -> bool:
        """True when the component has a local workspace to build."""
        return self.folder is not None


def _environment_schema(schema: dict[str, Any]) -> None:
    """Names are POSIX names; values are text, numbers or booleans (robocore writes them as text)."""
    schema.pop("patternProperties", None)
    schema["propertyNames"] = {"pattern": schema_pattern(ENV_NAME)}
    schema["additionalProperties"] = {"type": ["string", "number", "boolean"], "pattern": schema_pattern(MULTI_LINE)}


def _scalar_text(value: object) -> object:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return str(value)
    return value


class Robot(Strict):
    """A whole robot: one robot.yaml."""

    ros_distro: RosDistro
    ros_domain_id: Number = Field(default=0, ge=0, le=232, description="DDS domain id (0-232).")
    registry: Registry | None = None
    image_prefix: ImagePrefix = ""
    base: BaseImage = Field(default_factory=BaseImage)
    discovery: Discovery = Field(default_factory=Discovery)
    hosts: list[Host] = Field(min_length=1)
    common_packages: list[CommonPackage] = Field(default_factory=list)
    components: list[Component] = Field(default_factory=list)

    def host(self, name: str) -> Host:
        """The host called ``name`` (KeyError if none)."""
        for host in self.hosts:
            if host.name == name:
                return host
        raise KeyError(name)

    def component(self, name: str) -> Component:
        """The component called ``name`` (KeyError if none)."""
        for comp in self.components:
            if comp.name == name:
                return comp
        raise KeyError(name)

    def components_on(self, host: str) -> list[Component]:
        """Components that run on ``host``, in file order."""
        return [c for c in self.components if c.runs_on == host]

    def hosts_in_use(self) -> list[Host]:
        """Hosts that run a component or a discovery server, in file order (a spare machine is not one)."""
        used = {c.runs_on for c in self.components} | {s.host for s in self.discovery_servers}
        return [h for h in self.hosts if h.name in used]

    @property
    def generation(self) -> str:
        """``ROS 1`` or ``ROS 2``, for messages."""
        return f"ROS {self.ros_version}"

    @property
    def ros_version(self) -> int:
        """1 for a ROS 1 distro (melodic, noetic), else 2."""
        return 1 if self.ros_distro.value in ROS1_DISTROS else 2

    @property
    def discovery_kind(self) -> str:
        """robot.yaml's ``discovery.kind``, else the distro's own: ``rosmaster`` for ROS 1, ``fastdds`` for ROS 2."""
        if self.discovery.kind is not None:
            return self.discovery.kind
        return "rosmaster" if self.ros_version == 1 else "fastdds"

    @property
    def discovery_servers(self) -> list[DiscoveryServer]:
        """Configured discovery servers, or one on the first host; each with its port (the kind's default
        when robot.yaml gives none)."""
        servers = list(self.discovery.servers) or [DiscoveryServer(host=self.hosts[0].name)]
        return [s if s.port is not None else s.model_copy(update={"port": self.server_port(s)}) for s in servers]

    def server_port(self, server: DiscoveryServer) -> int:
        """The port of ``server``: its own, else the discovery kind's default."""
        if server.port is not None:
            return server.port
        return DEFAULT_PORTS.get(self.discovery_kind, DEFAULT_PORTS["fastdds"])

    @property
    def fastdds_line(self) -> int:
        """The Fast DDS major version of the distro (2 or 3)."""
        return FASTDDS_LINE[self.ros_distro.value]


#: Host names that name this machine: Debian's and Red Hat's ``/etc/hosts`` entries for 127.0.0.1 and ::1.
LOOPBACK_NAMES = frozenset({"localhost", "localhost.localdomain", "ip6-localhost", "ip6-loopback", "localhost6",
                            "localhost6.localdomain6"})


def is_loopback_address(address: str) -> bool:
    """True for loopback addresses, the names of :data:`LOOPBACK_NAMES` and every name under ``localhost``
    (``robot.localhost``: RFC 6761 reserves them for loopback, and systemd-resolved answers them so)."""
    name = address.lower().rstrip(".")
    if name in LOOPBACK_NAMES or name.endswith(".localhost"):
        return True
    try:
        found = ipaddress.ip_address(address.strip("[]"))
    except ValueError:
        return False
    mapped = found.ipv4_mapped if isinstance(found, ipaddress.IPv6Address) else None
    return (mapped or found).is_loopback
