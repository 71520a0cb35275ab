"""The discovery interface: what a discovery kind (Fast DDS discovery server, ROS 1 master, ...) provides.

A kind is a :class:`Discovery` subclass bound to one robot and one :class:`Transport`. It says
which server containers run where and what they run (:class:`ServerProcess`), the environment
of every node (client) and of every tool that must see the whole graph (observer), the files
those processes read (written to ``.robocore/dds/`` and mounted at ``naming.CONTAINER_DDS``),
when a server container is ready (a pure function of its log and state) and how to list the live
nodes from inside a server container. Everything else (container specs, compose files, ``run``,
``down``, ``status``, the dev shell, the pytest plugin) asks the kind and never branches on it.

Pure data and functions, no I/O.
"""

from __future__ import annotations

import re
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import ClassVar, Literal

from robocore.config.model import Robot
from robocore.plan.naming import CONTAINER_DDS

#: Where a process finds the kind's files: file name -> the path it reads it at, None when it has no copy.
FileLocator = Callable[[str], "str | None"]


def in_folder(folder: str) -> FileLocator:
    """A locator for a process that sees every file of :meth:`Discovery.files` in ``folder``."""

    def locate(name: str) -> str:
        return f"{folder}/{name}"

    return locate


def no_files(name: str) -> None:
    """The locator of a process that has none of the files (a tool exec'd into a server container)."""
    return None


#: Robocore's containers: the files are mounted at ``naming.CONTAINER_DDS``.
IN_CONTAINERS: FileLocator = in_folder(CONTAINER_DDS)


@dataclass(frozen=True)
class Transport:
    """How data moves between the robot's processes: shared memory between the containers of one host, or UDP only.

    The one place that turns robot.yaml's ``discovery.transport`` into a decision. Containers ask it
    for their IPC namespace; each discovery kind renders it into its own environment and files
    (Fast DDS: ``FASTDDS_BUILTIN_TRANSPORTS`` and a UDP transport descriptor).
    """

    shared_memory: bool

    @classmethod
    def of(cls, robot: Robot) -> Transport:
        """The robot's transport as robot.yaml sets it (``shm`` by default)."""
        return cls(shared_memory=robot.discovery.transport == "shm")

    def ipc_mode(self, network_mode: str) -> str | None:
        """``host`` for a host-networked container when the robot shares memory between containers, else None.

        Containers with host networking look co-located to the middleware, which then sends data
        through shared memory: without a shared IPC namespace they discover each other and receive
        nothing. On a bridge network the others do not look local and UDP is used anyway.
        """
        return "host" if self.shared_memory and network_mode == "host" else None


#: UDP only: the transport of a process that cannot share the containers' memory (the test process).
UDP = Transport(shared_memory=False)


@dataclass(frozen=True)
class ServerEndpoint:
    """Where server ``index`` of the robot listens: its robot host, that host's address and a port."""

    index: int
    host: str  # host name in robot.yaml
    address: str  # the host's ip (address or DNS name)
    port: int

    @property
    def locator(self) -> str:
        """``address:port``."""
        return f"{self.address}:{self.port}"


@dataclass(frozen=True)
class ServerProcess:
    """What one server container runs, in the robot's base image behind robocore's entrypoint.

    :func:`robocore.plan.containers.discovery_spec` turns it into a container (host network, the
    transport's IPC mode, a named state volume at ``state_dir`` when there is one).
    """

    command: tuple[str, ...]
    environment: Mapping[str, str]
    #: Where a named volume that outlives the container is mounted (None: the server keeps no state).
    #: A full ``down`` removes it, so that the next start is a first start.
    state_dir: str | None = None


@dataclass(frozen=True)
class ServerState:
    """What the wait loop knows of a server container besides its log."""

    status: str  # Docker's status: created, running, restarting, exited, dead...
    restart_count: int = 0
    timed_out: bool = False  # the wait loop's deadline has passed


#: Docker statuses of a container that is not (or no longer) running its first start.
STOPPED = frozenset({"exited", "dead", "restarting"})


@dataclass(frozen=True)
class Readiness:
    """A server container's readiness: ready, waiting, or failed with a reason (and a hint for the user)."""

    state: Literal["ready", "waiting", "failed"]
    reason: str = ""
    hint: str | None = None

    @property
    def ready(self) -> bool:
        """The server serves."""
        return self.state == "ready"

    @property
    def failed(self) -> bool:
        """The server will not serve: stop waiting and report :attr:`reason`."""
        return self.state == "failed"


READY = Readiness("ready")
WAITING = Readiness("waiting")
#: The readiness check the wait loops call: (log text, state) -> readiness.
ReadinessCheck = Callable[[str, ServerState], Readiness]

_ANSI = re.compile(r"\x1b\[[0-9;]*m")


def plain_text(log_text: str) -> str:
    """``log_text`` without terminal colour codes."""
    return _ANSI.sub("", log_text)


def last_error_line(log_text: str) -> str:
    """The last line of a log that looks like an error, else its last line, else ``no output``."""
    lines = [line.strip() for line in plain_text(log_text).splitlines() if line.strip()]
    errors = [line for line in lines if "rror" in line or "failed" in line]
    return (errors or lines or ["no output"])[-1]


class Discovery(ABC):
    """How the nodes of one robot find each other: a discovery kind bound to a robot and a transport."""

    #: The value of robot.yaml's ``discovery.kind`` this class implements.
    kind: ClassVar[str]
    #: The file of :meth:`files` that an observer reads (None: observers read no file).
    observer_file: ClassVar[str | None] = None
    #: The file of :meth:`files` that an observer living in a long process (the test process, which may bring up
    #: several robots) reads. Fast DDS reads a process's profile file once, at its first participant, so this file
    #: holds nothing of one robot (no server list): the servers come from the environment, which Fast DDS reads
    #: for each new participant. None: such observers read no file.
    probe_file: ClassVar[str | None] = None
    #: What a stopped server means for the running nodes, said by ``status`` (empty: nothing to add).
    server_down: ClassVar[str] = ""
    #: Nodes register with a server only when they start (ROS 1): ``run`` restarts the nodes of a host
    #: whose server it (re)starts.
    nodes_register_once: ClassVar[bool] = False

    def __init__(self, robot: Robot, transport: Transport | None = None) -> None:
        self.robot = robot
        self.transport = transport if transport is not None else Transport.of(robot)

    @abstractmethod
    def servers(self) -> Sequence[ServerEndpoint]:
        """Every server of the robot, in id order (the ids are the indexes)."""

    def servers_on(self, host: str) -> list[ServerEndpoint]:
        """The servers that run on robot host ``host``, in id order."""
        return [s for s in self.servers() if s.host == host]

    @abstractmethod
    def server_process(self, index: int) -> ServerProcess:
        """What the container of server ``index`` runs: command, environment, state folder."""

    @abstractmethod
    def client_environment(self, host: str, files: FileLocator = IN_CONTAINERS, *,
                           network_mode: str = "host") -> dict[str, str]:
        """Environment of a node running on robot host ``host`` (a component), its files found by ``files``.

        ``network_mode``: the container's network (``host`` or ``bridge``), for kinds whose nodes must
        tell others their own address."""

    @abstractmethod
    def observer_environment(self, host: str | None = None, files: FileLocator = IN_CONTAINERS) -> dict[str, str]:
        """Environment of a tool that sees the whole graph (``status``, ``connect``, the dev shell, the test process).

        ``host`` is the robot host it runs on, None off the robot (the developer's machine).
        """

    def successor_environment(self, previous: Mapping[str, str], planned: Mapping[str, str]) -> dict[str, str]:
        """The environment of a node container replacing one whose environment was ``previous`` (``planned`` by
        default; a kind whose replacements would inherit their predecessor's state through the host changes it)."""
        del previous
        return dict(planned)

    @abstractmethod
    def files(self) -> dict[str, str]:
        """The files nodes and tools read: file name -> text (written to ``.robocore/dds/``)."""

    @abstractmethod
    def readiness(self, log_text: str, state: ServerState) -> Readiness:
        """Whether a server container serves, from the tail of its log and its state (a pure function)."""

    @abstractmethod
    def node_list_argv(self, spin_seconds: float) -> list[str]:
        """argv that prints the live nodes, run in a server container with :meth:`observer_environment`."""

    def nodes_from_output(self, text: str) -> list[str]:
        """The node names in the output of :meth:`node_list_argv`: fully qualified, hidden nodes left out."""
        names = sorted({line.strip() for line in text.splitlines() if line.strip().startswith("/")})
        return [n for n in names if not n.split("/")[-1].startswith("_")]
