"""Fast DDS discovery-server configuration: environment, XML profiles and server argv.

Pure functions of a :class:`~robocore.config.model.Robot`. Two Fast DDS lines matter
(see the robot's ``fastdds_line``):

* **2.x** (Humble, Jazzy): a server's *position* in ``ROS_DISCOVERY_SERVER`` is its id;
  the server is started with ``-i <id>``; XML lists servers as ``<RemoteServer prefix=...>``;
  the profile file is read from ``FASTRTPS_DEFAULT_PROFILES_FILE``.
* **3.x** (Kilted, Rolling): servers are matched by locator only; XML lists bare
  ``<locator>`` elements; the profile file is read from ``FASTDDS_DEFAULT_PROFILES_FILE``.

Profiles are named by ``FASTDDS_DEFAULT_PROFILES_FILE`` on both lines, plus
``FASTRTPS_DEFAULT_PROFILES_FILE`` on 2.x (3.x warns about that old name).
Server ids are the indexes of ``robot.discovery_servers``; several servers are redundant:
every participant lists all of them, and servers list each other.
"""

from __future__ import annotations

from dataclasses import dataclass
from xml.sax.saxutils import escape

from robocore.config.model import Robot
from robocore.plan.naming import CONTAINER_DDS

RMW = "rmw_fastrtps_cpp"

#: Profile files robocore writes to ``.robocore/dds/`` (mounted at ``CONTAINER_DDS``).
SUPER_CLIENT_PROFILE = "super_client.xml"
CLIENT_PROFILE = "client.xml"

_PREFIX_TAIL = "5f.45.50.52.4f.53.49.4d.41"  # "_EPROSIMA"
_NS = {2: "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles", 3: "http://www.eprosima.com"}


@dataclass(frozen=True)
class ServerEndpoint:
    """Where discovery server ``index`` listens: its host's address and a UDP port."""

    index: int
    host: str  # host name in robot.yaml
    address: str  # the host's ip (address or DNS name)
    port: int

    @property
    def locator(self) -> str:
        """``address:port`` as written in ROS_DISCOVERY_SERVER."""
        return f"{self.address}:{self.port}"

    @property
    def guid_prefix(self) -> str:
        """The 2.x server GUID prefix ``44.53.<id>.5f.45.50.52.4f.53.49.4d.41`` ("DS<id>_EPROSIMA")."""
        return f"44.53.{self.index:02x}.{_PREFIX_TAIL}"


def servers(robot: Robot) -> list[ServerEndpoint]:
    """Every discovery server of the robot, in id order (default: one on the first host)."""
    out = []
    for index, server in enumerate(robot.discovery_servers):
        host = robot.host(server.host)
        out.append(ServerEndpoint(index=index, host=host.name, address=host.ip, port=server.port))
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


def _profile_env(robot: Robot, file_name: str) -> dict[str, str]:
    """2.x reads FASTRTPS_DEFAULT_PROFILES_FILE (both are set, as on 3.x); 3.x reads FASTDDS_DEFAULT_PROFILES_FILE
    and warns that the FASTRTPS_ name is deprecated (verified with Kilted's rmw_fastrtps), so it gets only that."""
    path = f"{CONTAINER_DDS}/{file_name}"
    if robot.fastdds_line >= 3:
        return {"FASTDDS_DEFAULT_PROFILES_FILE": path}
    return {"FASTRTPS_DEFAULT_PROFILES_FILE": path, "FASTDDS_DEFAULT_PROFILES_FILE": path}


def transport_environment(robot: Robot) -> dict[str, str]:
    """Transport settings shared by clients and servers (UDP only when asked)."""
    if robot.discovery.transport == "udp":
        return {"FASTDDS_BUILTIN_TRANSPORTS": "UDPv4"}
    return {}


def client_environment(robot: Robot, *, super_client: bool = False) -> dict[str, str]:
    """Environment of a ROS participant: a component (client) or a tool (``super_client``).

    A super client sees the whole graph (``ros2 node list``, connect, shell); it gets both
    ``ROS_SUPER_CLIENT`` and the SUPER_CLIENT XML profile, which lists the same servers. A plain
    client gets the client profile (:func:`client_xml`): discovery timing, and the transport on
    Humble; it leaves the discovery protocol alone, so ``ROS_DISCOVERY_SERVER`` still applies.
    """
    env = {
        "ROS_DOMAIN_ID": str(robot.ros_domain_id),
        "RMW_IMPLEMENTATION": RMW,
        "ROS_DISCOVERY_SERVER": discovery_server_value(robot),
    }
    env.update(transport_environment(robot))
    if super_client:
        env["ROS_SUPER_CLIENT"] = "TRUE"
        env.update(_profile_env(robot, SUPER_CLIENT_PROFILE))
    else:
        env.update(_profile_env(robot, CLIENT_PROFILE))
    return env


def server_environment(robot: Robot, index: int) -> dict[str, str]:
    """Environment of discovery server ``index``: the other servers (redundancy), own slot empty.

    Servers need no profile file: clients restricted to UDP simply use the server's UDP locators.
    """
    env = {"ROS_DOMAIN_ID": str(robot.ros_domain_id)}
    others = discovery_server_value(robot, exclude=index)
    if others.strip(";"):
        env["ROS_DISCOVERY_SERVER"] = others
    env.update(transport_environment(robot))
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
#: (Fast DDS defaults: 450 ms, and 5 x 100 ms). Measured on Jazzy (host network, one server): with
#: the defaults a node started next to a running peer matched it after 0.5 - 1 s, so a publisher's
#: first message on a 0.5 s timer was lost (10 of 10 starts); with these it matched in time in 21 of
#: 22 starts, as fast as without a server. A client stops announcing once a server has answered: the cost is a few
#: small packets at start.
CLIENT_ANNOUNCEMENT_MS = 50
INITIAL_ANNOUNCEMENTS = (5, 50)  # count, period in ms
#: How often a server repeats what its clients have not acknowledged yet (default 450 ms).
SERVER_ANNOUNCEMENT_MS = 100


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


#: Liveliness of discovery servers as their clients see it. Shorter than Fast DDS's 20 s default so that
#: a restarted server is usable sooner (see :func:`restart_hold_seconds`).
SERVER_LEASE_SECONDS = 8
SERVER_ANNOUNCEMENT_SECONDS = 2


def restart_hold_seconds(robot: Robot) -> int:
    """Seconds a *restarted* discovery server waits before serving.

    A 2.x server restarts with the same GUID (its ``-i`` id). Its clients keep the proxy of the
    previous instance, whose liveliness the new instance keeps refreshing, and they discard what
    the new instance sends (its sequence numbers start again): a participant started after the
    restart never matches one started before it (measured with Jazzy's Fast DDS 2.14: no
    recovery in 90 s). Staying silent for longer than the server's lease makes every client drop
    the old proxy and register again from scratch, which takes a few seconds. Fast DDS 3.x
    servers get a new GUID on every start (no ``-i``) and need no hold.
    """
    return SERVER_LEASE_SECONDS + 4 if robot.fastdds_line < 3 else 0


def server_profile_xml(robot: Robot) -> str:
    """The server's own profile (``fastdds discovery -x``): SERVER with robocore's lease settings, one line."""
    ns = _NS[3 if robot.fastdds_line >= 3 else 2]
    return (
        f'<?xml version="1.0" encoding="UTF-8"?><dds><profiles xmlns="{ns}">'
        '<participant profile_name="robocore_server" is_default_profile="true"><rtps><builtin><discovery_config>'
        "<discoveryProtocol>SERVER</discoveryProtocol>"
        f"<leaseDuration><sec>{SERVER_LEASE_SECONDS}</sec></leaseDuration>"
        f"<leaseAnnouncement><sec>{SERVER_ANNOUNCEMENT_SECONDS}</sec></leaseAnnouncement>"
        + _timing("", SERVER_ANNOUNCEMENT_MS, initial=False).strip()
        + "</discovery_config></builtin></rtps></participant></profiles></dds>"
    )


def profile_files(robot: Robot) -> dict[str, str]:
    """The XML profiles to write to ``.robocore/dds/``: file name -> XML text."""
    return {SUPER_CLIENT_PROFILE: super_client_xml(robot), CLIENT_PROFILE: client_xml(robot)}


def _locator(address: str, port: int, indent: str) -> str:
    return (
        f"{indent}<locator><udpv4><address>{escape(address)}</address>"
        f"<port>{port}</port></udpv4></locator>\n"
    )


def _udp_transport(robot: Robot) -> tuple[str, str]:
    """(descriptors block, participant rtps block) for UDP-only, or empty strings."""
    if robot.discovery.transport != "udp":
        return "", ""
    descriptors = (
        "    <transport_descriptors>\n"
        "      <transport_descriptor>\n"
        "        <transport_id>robocore_udp</transport_id>\n"
        "        <type>UDPv4</type>\n"
        "      </transport_descriptor>\n"
        "    </transport_descriptors>\n"
    )
    rtps = (
        "        <userTransports><transport_id>robocore_udp</transport_id></userTransports>\n"
        "        <useBuiltinTransports>false</useBuiltinTransports>\n"
    )
    return descriptors, rtps


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


def super_client_xml(robot: Robot) -> str:
    """The SUPER_CLIENT participant profile (default profile) listing every server."""
    descriptors, transport = _udp_transport(robot)
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
        f"{transport}"
        "        <builtin>\n"
        "          <discovery_config>\n"
        "            <discoveryProtocol>SUPER_CLIENT</discoveryProtocol>\n"
        f"{_timing('            ', CLIENT_ANNOUNCEMENT_MS, initial=True)}"
        "            <discoveryServersList>\n"
        f"{''.join(entries)}"
        "            </discoveryServersList>\n"
        "          </discovery_config>\n"
        "        </builtin>\n"
        "      </rtps>\n"
        "    </participant>\n"
    )
    return _document(robot, descriptors, participant)


def client_xml(robot: Robot) -> str:
    """The plain client profile: discovery timing (and UDP only when asked); the servers still come
    from ``ROS_DISCOVERY_SERVER``, because the profile leaves the discovery protocol alone."""
    descriptors, transport = _udp_transport(robot)
    participant = (
        '    <participant profile_name="robocore_client" is_default_profile="true">\n'
        "      <rtps>\n"
        f"{transport}"
        "        <builtin>\n"
        "          <discovery_config>\n"
        f"{_timing('            ', CLIENT_ANNOUNCEMENT_MS, initial=True)}"
        "          </discovery_config>\n"
        "        </builtin>\n"
        "      </rtps>\n"
        "    </participant>\n"
    )
    return _document(robot, descriptors, participant)
