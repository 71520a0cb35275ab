"""The Fast DDS discovery server: server containers, environment, XML profiles and readiness.

The ``fastdds`` discovery kind (robot.yaml's default ``discovery.kind``). Two Fast DDS lines
matter (see the robot's ``fastdds_line``); their differences stay in this module:

* **2.x** (Humble, Jazzy): a server's *position* in ``ROS_DISCOVERY_SERVER`` is its id;
  the server is started with ``-i <id>``; XML lists servers as ``<RemoteServer prefix=...>``;
  the profile file is read from ``FASTRTPS_DEFAULT_PROFILES_FILE``; a restarted server holds
  back before serving (:func:`restart_hold_seconds`).
* **3.x** (Kilted, Rolling): servers are matched by locator only; XML lists bare
  ``<locator>`` elements; the profile file is read from ``FASTDDS_DEFAULT_PROFILES_FILE``; a server's
  lease is shorter and a restarted server serves at once (:func:`server_liveliness`).

Profiles are named by ``FASTDDS_DEFAULT_PROFILES_FILE`` on both lines, plus
``FASTRTPS_DEFAULT_PROFILES_FILE`` on 2.x (3.x warns about that old name).
Server ids are the indexes of ``robot.discovery_servers``; several servers are redundant:
every participant lists all of them, and servers list each other.

The module functions take the robot (and, where it matters, a transport other than the robot's);
:class:`FastDds` is the same behind the :class:`~robocore.plan.discovery.base.Discovery` interface.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from xml.sax.saxutils import escape

from robocore.config.model import Robot
from robocore.plan.discovery.base import (
    IN_CONTAINERS,
    READY,
    STOPPED,
    WAITING,
    Discovery,
    FileLocator,
    Readiness,
    ServerEndpoint,
    ServerProcess,
    ServerState,
    Transport,
    last_error_line,
    plain_text,
)
from robocore.plan.discovery.fastdds_transports import TransportSettings, transport_settings
from robocore.plan.discovery.replacements import rotate_profile
from robocore.plan.discovery.server_script import DISCOVERY_PROFILE, DISCOVERY_SCRIPT, DISCOVERY_STATE
from robocore.plan.naming import ENTRYPOINT, INIT_SIGNALS_GROUP

RMW = "rmw_fastrtps_cpp"

#: Profile files robocore writes to ``.robocore/dds/`` (mounted at ``naming.CONTAINER_DDS``).
SUPER_CLIENT_PROFILE = "super_client.xml"
CLIENT_PROFILE = "client.xml"
#: The client profiles a node's successive replacements on a host go round: file -> user port offset (``offsetd3``;
#: None: Fast DDS's 11). A replacement on its predecessor's ports (same participant id) is not heard while peers
#: still write into the dead one's shared memory, until Fast DDS notices; a new offset gives it ports of its own.
#: Four, as `dev` can replace a node twice in that time (its first deploy, then a save). Odd offsets 100 apart
#: never meet a discovery port (10 + 2 x id), nor each other below 50 participants on a host. The measurements:
#: docs/design-notes.md, "Four client profiles in rotation".
CLIENT_ROTATION: dict[str, int | None] = {CLIENT_PROFILE: None, "client-1.xml": 111, "client-2.xml": 211,
                                          "client-3.xml": 311}
#: The variables that name a process's profile file.
PROFILE_VARIABLES = ("FASTDDS_DEFAULT_PROFILES_FILE", "FASTRTPS_DEFAULT_PROFILES_FILE")

_PREFIX_TAIL = "5f.45.50.52.4f.53.49.4d.41"  # "_EPROSIMA"
_NS = {2: "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles", 3: "http://www.eprosima.com"}


@dataclass(frozen=True)
class FastDdsServer(ServerEndpoint):
    """A discovery server's endpoint, with the GUID prefix Fast DDS 2.x derives from its id."""

    @property
    def guid_prefix(self) -> str:
        """The 2.x server GUID prefix ``44.53.<id>.5f.45.50.52.4f.53.49.4d.41`` ("DS<id>_EPROSIMA")."""
        return f"44.53.{self.index:02x}.{_PREFIX_TAIL}"


def servers(robot: Robot) -> list[FastDdsServer]:
    """Every discovery server of the robot, in id order (default: one on the first host)."""
    out = []
    for index, server in enumerate(robot.discovery_servers):
        host = robot.host(server.host)
        out.append(FastDdsServer(index=index, host=host.name, address=host.ip, port=robot.server_port(server)))
    return out


def discovery_server_value(robot: Robot, *, exclude: int | None = None) -> str:
    """The ``ROS_DISCOVERY_SERVER`` value: positional slots on 2.x, a locator list on 3.x.

    ``exclude`` leaves out one server (a server's own entry in its own environment);
    on 2.x its slot stays empty so that the other servers keep their ids.
    """
    endpoints = servers(robot)
    if robot.fastdds_line >= 3:
        return ";".join(s.locator for s in endpoints if s.index != exclude)
    slots = ["" if s.index == exclude else s.locator for s in endpoints]
    while slots and not slots[-1]:
        slots.pop()
    return ";".join(slots)


def _profile_env(robot: Robot, path: str | None) -> dict[str, str]:
    """2.x reads FASTRTPS_DEFAULT_PROFILES_FILE (both are set, as on 3.x); 3.x reads FASTDDS_DEFAULT_PROFILES_FILE
    and warns that the FASTRTPS_ name is deprecated (verified with Kilted's rmw_fastrtps), so it gets only that.
    ``path`` None (the process has no copy of the profile): neither."""
    if path is None:
        return {}
    if robot.fastdds_line >= 3:
        return {"FASTDDS_DEFAULT_PROFILES_FILE": path}
    return {"FASTRTPS_DEFAULT_PROFILES_FILE": path, "FASTDDS_DEFAULT_PROFILES_FILE": path}


def _transport(robot: Robot, transport: Transport | None) -> TransportSettings:
    return transport_settings(Transport.of(robot) if transport is None else transport)


def client_environment(robot: Robot, *, super_client: bool = False, transport: Transport | None = None,
                       files: FileLocator = IN_CONTAINERS) -> dict[str, str]:
    """Environment of a ROS participant: a component (client) or a tool (``super_client``).

    A super client sees the whole graph (``ros2 node list``, connect, shell); it gets both
    ``ROS_SUPER_CLIENT`` and the SUPER_CLIENT XML profile, which lists the same servers. A plain
    client gets the client profile (:func:`client_xml`): discovery timing, and the transport on
    Humble; it leaves the discovery protocol alone, so ``ROS_DISCOVERY_SERVER`` still applies.
    ``transport`` defaults to the robot's; ``files`` says where the process finds the profiles.
    """
    env = {
        "ROS_DOMAIN_ID": str(robot.ros_domain_id),
        "RMW_IMPLEMENTATION": RMW,
        "ROS_DISCOVERY_SERVER": discovery_server_value(robot),
    }
    env.update(_transport(robot, transport).environment)
    if super_client:
        env["ROS_SUPER_CLIENT"] = "TRUE"
        env.update(_profile_env(robot, files(SUPER_CLIENT_PROFILE)))
    else:
        env.update(_profile_env(robot, files(CLIENT_PROFILE)))
    return env


def server_environment(robot: Robot, index: int, *, transport: Transport | None = None) -> dict[str, str]:
    """Environment of discovery server ``index``: the other servers (redundancy), own slot empty.

    Servers need no profile file: clients restricted to UDP simply use the server's UDP locators.
    """
    env = {"ROS_DOMAIN_ID": str(robot.ros_domain_id)}
    others = discovery_server_value(robot, exclude=index)
    if others.strip(";"):
        env["ROS_DISCOVERY_SERVER"] = others
    env.update(_transport(robot, transport).environment)
    return env


def server_command(robot: Robot, index: int) -> list[str]:
    """argv of ``fastdds discovery`` for server ``index`` (``-i`` on 2.x, where it is mandatory)."""
    endpoint = servers(robot)[index]
    argv = ["fastdds", "discovery"]
    if robot.fastdds_line < 3:
        argv += ["-i", str(index)]
    argv += ["-l", "0.0.0.0", "-p", str(endpoint.port)]
    return argv


#: How often a client announces itself to the servers until one answers, and the first announcements
#: (Fast DDS defaults: 450 ms, and 5 x 100 ms). With the defaults a node started next to a running peer matches
#: it too late for the first message of a publisher on a 0.5 s timer; at 20 ms a restarted node matches its
#: peers about as fast as without a server. A client stops announcing once a server has answered: the cost is a
#: few small packets at start. The measurements: docs/design-notes.md, "Discovery timing: 20 ms".
CLIENT_ANNOUNCEMENT_MS = 20
INITIAL_ANNOUNCEMENTS = (5, 20)  # count, period in ms
#: How often a server runs its discovery routine: it passes what it learnt on to its clients and repeats what
#: they have not acknowledged yet (default 450 ms). 20 ms for the same reason as the clients' period; a shorter
#: period matched no sooner.
SERVER_ANNOUNCEMENT_MS = 20
#: A client's discovery traffic (what servers and peers send it) goes over UDP, whatever the transport of its
#: data. With shared memory, a node's replacement on the same host reuses the shared-memory port of the process
#: it replaces, while the server and the other nodes may still hold the old port's memory and write into it
#: until Fast DDS's watchdog (a 1 s period) finds its reader dead: the new node then heard nothing of the graph
#: for up to a few seconds, which discovery over UDP avoids. Data between the nodes of one host still goes through
#: shared memory. No address and port 0: Fast DDS listens on this host's interfaces at the participant's usual
#: metatraffic port. The measurements: docs/design-notes.md, "Discovery traffic over UDP, data over shared memory".
METATRAFFIC_OVER_UDP = (
    "          <metatrafficUnicastLocatorList><locator><udpv4/></locator></metatrafficUnicastLocatorList>\n"
)


def _duration(ms: int) -> str:
    return f"<sec>{ms // 1000}</sec><nanosec>{(ms % 1000) * 1_000_000}</nanosec>"


def _timing(indent: str, period_ms: int, *, initial: bool) -> str:
    """``discovery_config`` elements that make discovery through a server quick."""
    lines = [f"{indent}<clientAnnouncementPeriod>{_duration(period_ms)}</clientAnnouncementPeriod>\n"]
    if initial:
        count, period = INITIAL_ANNOUNCEMENTS
        lines.append(f"{indent}<initialAnnouncements><count>{count}</count>"
                     f"<period>{_duration(period)}</period></initialAnnouncements>\n")
    return "".join(lines)


@dataclass(frozen=True)
class ServerLiveliness:
    """How long a discovery server's clients keep it alive without news (``lease_ms``), how often it announces
    itself to them (``announcement_ms``), and how long a *restarted* server stays silent first (``hold_seconds``):
    one per Fast DDS line (:data:`SERVER_LIVELINESS`), as the lease decides how soon a killed server's clients
    find its successor."""

    lease_ms: int
    announcement_ms: int
    hold_seconds: int


#: The servers' liveliness per Fast DDS line (both shorter than Fast DDS's 20 s lease announced every 3 s).
#: * 2.x: a restarted server has its old GUID (``-i``), and its clients discard what it sends until its lease ran
#:   out: it holds back for the lease plus 4 s. Shorter leases with shorter holds let matched nodes go unheard.
#: * 3.x: a restarted server has a new GUID and serves at once, but a client matches the successor's discovery
#:   endpoints only once it dropped the killed instance (Fast DDS 3.2 does it in its ping routine, which restarts
#:   when a server leaves): a node started after a restart is heard about a lease after the kill. Kilted, from the
#:   kill: 8 s heard after 8.0 s median, 3 s after 2.9 s (1.1 s from the node's start), matched nodes missing
#:   nothing (docs/design-notes.md, "A restarted Fast DDS 3.x server serves at once").
SERVER_LIVELINESS = {
    2: ServerLiveliness(lease_ms=8000, announcement_ms=2000, hold_seconds=12),
    3: ServerLiveliness(lease_ms=3000, announcement_ms=1000, hold_seconds=0),
}


def _lease_duration(ms: int) -> str:
    """Whole seconds as ``<sec>`` alone (the 2.x profile's text, unchanged), anything else with ``<nanosec>``."""
    return f"<sec>{ms // 1000}</sec>" if ms % 1000 == 0 else _duration(ms)


def server_liveliness(robot: Robot) -> ServerLiveliness:
    """The robot's Fast DDS line's server lease, announcement period and restart hold (:data:`SERVER_LIVELINESS`)."""
    return SERVER_LIVELINESS[3 if robot.fastdds_line >= 3 else 2]


def restart_hold_seconds(robot: Robot) -> int:
    """Seconds a *restarted* discovery server waits before serving.

    A 2.x server restarts with the same GUID (its ``-i`` id). Its clients keep the proxy of the previous
    instance, whose liveliness the new instance keeps refreshing, and they discard what the new instance
    sends (its sequence numbers start again): a participant started after the restart never matches one
    started before it (Jazzy's Fast DDS 2.14: no recovery in 90 s). Staying silent for longer than the
    server's lease makes every client drop the old proxy and register again from scratch. Fast DDS 3.x
    servers get a new GUID on every start (no ``-i``) and need no hold. A BACKUP server (``-b``), Fast DDS's
    own remedy, aborts when it reloads its files on restart in 2.14 (``bench/server_restart.py``).
    """
    return server_liveliness(robot).hold_seconds


def server_profile_xml(robot: Robot, liveliness: ServerLiveliness | None = None) -> str:
    """The server's own profile (``fastdds discovery -x``): SERVER with its line's lease settings (or
    ``liveliness``'s: the bench's contrasts), one line."""
    ns = _NS[3 if robot.fastdds_line >= 3 else 2]
    live = server_liveliness(robot) if liveliness is None else liveliness
    return (
        f'<?xml version="1.0" encoding="UTF-8"?><dds><profiles xmlns="{ns}">'
        '<participant profile_name="robocore_server" is_default_profile="true"><rtps><builtin><discovery_config>'
        "<discoveryProtocol>SERVER</discoveryProtocol>"
        f"<leaseDuration>{_lease_duration(live.lease_ms)}</leaseDuration>"
        f"<leaseAnnouncement>{_lease_duration(live.announcement_ms)}</leaseAnnouncement>"
        + _timing("", SERVER_ANNOUNCEMENT_MS, initial=False).strip()
        + "</discovery_config></builtin></rtps></participant></profiles></dds>"
    )


def profile_files(robot: Robot, *, transport: Transport | None = None) -> dict[str, str]:
    """The XML profiles to write to ``.robocore/dds/``: file name -> XML text."""
    files = {SUPER_CLIENT_PROFILE: super_client_xml(robot, transport=transport)}
    files.update({name: client_xml(robot, transport=transport, user_port_offset=offset)
                  for name, offset in CLIENT_ROTATION.items()})
    return files


def successor_environment(previous: Mapping[str, str], planned: Mapping[str, str]) -> dict[str, str]:
    """A replacement node's environment: its client profile the one after its predecessor's in
    :data:`CLIENT_ROTATION`, so that replacements in quick succession never share ports."""
    return rotate_profile(previous, planned, variables=PROFILE_VARIABLES, rotation=list(CLIENT_ROTATION))


def _locator(address: str, port: int, indent: str) -> str:
    return (
        f"{indent}<locator><udpv4><address>{escape(address)}</address>"
        f"<port>{port}</port></udpv4></locator>\n"
    )


def _document(robot: Robot, descriptors: str, participant: str) -> str:
    ns = _NS[3 if robot.fastdds_line >= 3 else 2]
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        "<!-- Generated by robocore from robot.yaml; do not edit. -->\n"
        "<dds>\n"
        f'  <profiles xmlns="{ns}">\n'
        f"{descriptors}{participant}"
        "  </profiles>\n"
        "</dds>\n"
    )


def super_client_xml(robot: Robot, *, transport: Transport | None = None) -> str:
    """The SUPER_CLIENT participant profile (default profile) listing every server."""
    settings = _transport(robot, transport)
    entries = []
    for server in servers(robot):
        if robot.fastdds_line >= 3:
            entries.append(_locator(server.address, server.port, "              "))
        else:
            entries.append(
                f'              <RemoteServer prefix="{server.guid_prefix}">\n'
                "                <metatrafficUnicastLocatorList>\n"
                f"{_locator(server.address, server.port, '                  ')}"
                "                </metatrafficUnicastLocatorList>\n"
                "              </RemoteServer>\n"
            )
    participant = (
        '    <participant profile_name="robocore_super_client" is_default_profile="true">\n'
        "      <rtps>\n"
        f"{settings.rtps}"
        "        <builtin>\n"
        "          <discovery_config>\n"
        "            <discoveryProtocol>SUPER_CLIENT</discoveryProtocol>\n"
        f"{_timing('            ', CLIENT_ANNOUNCEMENT_MS, initial=True)}"
        "            <discoveryServersList>\n"
        f"{''.join(entries)}"
        "            </discoveryServersList>\n"
        "          </discovery_config>\n"
        f"{METATRAFFIC_OVER_UDP}"
        "        </builtin>\n"
        "      </rtps>\n"
        "    </participant>\n"
    )
    return _document(robot, settings.descriptors, participant)


def client_xml(robot: Robot, *, transport: Transport | None = None, user_port_offset: int | None = None) -> str:
    """The plain client profile: discovery timing (and UDP only when asked); the servers still come
    from ``ROS_DISCOVERY_SERVER``, because the profile leaves the discovery protocol alone. ``user_port_offset``:
    Fast DDS's ``offsetd3`` (see :data:`CLIENT_ROTATION`)."""
    settings = _transport(robot, transport)
    ports = "" if user_port_offset is None else f"        <port><offsetd3>{user_port_offset}</offsetd3></port>\n"
    participant = (
        '    <participant profile_name="robocore_client" is_default_profile="true">\n'
        "      <rtps>\n"
        f"{settings.rtps}"
        f"{ports}"
        "        <builtin>\n"
        "          <discovery_config>\n"
        f"{_timing('            ', CLIENT_ANNOUNCEMENT_MS, initial=True)}"
        "          </discovery_config>\n"
        f"{METATRAFFIC_OVER_UDP}"
        "        </builtin>\n"
        "      </rtps>\n"
        "    </participant>\n"
    )
    return _document(robot, settings.descriptors, participant)


# --------------------------------------------------------------------------- the server container

#: What a discovery server container logs once it serves (Fast DDS 2.x, 3.x) or while it holds after a restart.
SERVER_READY = ("Server is running", "Server started", "robocore: discovery server restarted")
#: The usual reason a server stops at start.
PORT_HINT = ("is another discovery server using its UDP port on that host? "
             "choose another port in robot.yaml (discovery.servers[].port)")


def server_process(robot: Robot, index: int, *, transport: Transport | None = None) -> ServerProcess:
    """What server ``index`` runs: :data:`DISCOVERY_SCRIPT` (restart hold, own profile), then ``fastdds discovery``."""
    env = server_environment(robot, index, transport=transport)
    env["ROBOCORE_DS_XML"] = server_profile_xml(robot)
    env["ROBOCORE_DS_HOLD"] = str(restart_hold_seconds(robot))
    env[INIT_SIGNALS_GROUP] = "1"  # a graceful stop reaches the server itself (see DISCOVERY_SCRIPT)
    command = ("sh", "-c", DISCOVERY_SCRIPT, "robocore-discovery", *server_command(robot, index),
               "-x", DISCOVERY_PROFILE)
    return ServerProcess(command=command, environment=env, state_dir=DISCOVERY_STATE)


def readiness(log_text: str, state: ServerState) -> Readiness:
    """Ready once the server says it serves (or holds after a restart); failed once it stopped or restarted.

    A restart count above zero means the first start already failed (usually the port is taken);
    the reason is the log's last error line.
    """
    text = plain_text(log_text)
    restarted = state.restart_count > 0
    if not restarted and any(marker in text for marker in SERVER_READY):
        return READY
    if restarted or state.status in STOPPED or state.timed_out:
        return Readiness("failed", last_error_line(text)[-200:], hint=PORT_HINT)
    return WAITING


class FastDds(Discovery):
    """Fast DDS discovery servers (robot.yaml ``discovery.kind: fastdds``): every node a client of them."""

    kind = "fastdds"
    observer_file = SUPER_CLIENT_PROFILE
    probe_file = CLIENT_PROFILE  # timing and transport only; ROS_SUPER_CLIENT and ROS_DISCOVERY_SERVER do the rest

    def servers(self) -> list[FastDdsServer]:
        """Every discovery server, in id order."""
        return servers(self.robot)

    def server_process(self, index: int) -> ServerProcess:
        """``fastdds discovery`` for server ``index``, behind the restart hold."""
        return server_process(self.robot, index, transport=self.transport)

    def client_environment(self, host: str, files: FileLocator = IN_CONTAINERS, *,
                           network_mode: str = "host") -> dict[str, str]:
        """A client of every server (neither the host nor the network matters to Fast DDS)."""
        return client_environment(self.robot, transport=self.transport, files=files)

    def observer_environment(self, host: str | None = None, files: FileLocator = IN_CONTAINERS) -> dict[str, str]:
        """A super client of every server."""
        return client_environment(self.robot, super_client=True, transport=self.transport, files=files)

    def files(self) -> dict[str, str]:
        """The client and super-client profiles, and the client profile of a replacement."""
        return profile_files(self.robot, transport=self.transport)

    def successor_environment(self, previous: Mapping[str, str], planned: Mapping[str, str]) -> dict[str, str]:
        """See :func:`successor_environment`."""
        return successor_environment(previous, planned)

    def readiness(self, log_text: str, state: ServerState) -> Readiness:
        """See :func:`readiness`."""
        return readiness(log_text, state)

    def node_list_argv(self, spin_seconds: float) -> list[str]:
        """``ros2 node list`` behind robocore's entrypoint, without the ROS 2 daemon."""
        return [ENTRYPOINT, "ros2", "node", "list", "--no-daemon", "--spin-time", str(spin_seconds)]
