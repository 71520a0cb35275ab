"""robocore.plan.discovery.fastdds: discovery-server environment, XML profiles and server argv per Fast DDS line."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from robocore.config.model import Robot
from robocore.plan.discovery import fastdds as dds
from robocore.plan.discovery.fastdds_transports import SHM_HEALTHY_CHECK_MS


def robot(distro: str = "jazzy", servers: list[dict[str, Any]] | None = None, hosts: int = 3,
          transport: str = "shm", domain: int = 7) -> Robot:
    data: dict[str, Any] = {
        "ros_distro": distro,
        "ros_domain_id": domain,
        "hosts": [{"name": f"h{i}", "ip": f"10.0.0.{i + 1}"} for i in range(hosts)],
        "discovery": {"transport": transport},
    }
    if servers is not None:
        data["discovery"]["servers"] = servers
    return Robot.model_validate(data)


def parse(xml: str) -> ET.Element:
    root = ET.fromstring(xml.encode())
    for element in root.iter():  # drop namespaces: the Fast DDS parser ignores them
        element.tag = element.tag.split("}")[-1]
    return root


# ------------------------------------------------------------------ environment


def test_default_server_is_first_host_on_11811() -> None:
    env = dds.client_environment(robot())
    assert env["ROS_DISCOVERY_SERVER"] == "10.0.0.1:11811"
    assert env["ROS_DOMAIN_ID"] == "7"
    assert env["RMW_IMPLEMENTATION"] == "rmw_fastrtps_cpp"
    assert "ROS_SUPER_CLIENT" not in env
    assert env["FASTRTPS_DEFAULT_PROFILES_FILE"] == env["FASTDDS_DEFAULT_PROFILES_FILE"] == "/robocore/dds/client.xml"


@pytest.mark.parametrize("distro", ["humble", "jazzy"])
def test_2x_slots_are_positional(distro: str) -> None:
    r = robot(distro, servers=[{"host": "h0"}, {"host": "h2", "port": 11900}])
    assert dds.discovery_server_value(r) == "10.0.0.1:11811;10.0.0.3:11900"
    # Each server lists the others, its own slot empty so the other ids keep their positions.
    assert dds.server_environment(r, 0)["ROS_DISCOVERY_SERVER"] == ";10.0.0.3:11900"
    assert dds.server_environment(r, 1)["ROS_DISCOVERY_SERVER"] == "10.0.0.1:11811"


def test_2x_middle_server_keeps_an_empty_slot() -> None:
    r = robot("humble", servers=[{"host": "h0"}, {"host": "h1"}, {"host": "h2"}])
    assert dds.server_environment(r, 1)["ROS_DISCOVERY_SERVER"] == "10.0.0.1:11811;;10.0.0.3:11811"


@pytest.mark.parametrize("distro", ["kilted", "rolling"])
def test_3x_is_a_locator_list_without_slots(distro: str) -> None:
    r = robot(distro, servers=[{"host": "h0"}, {"host": "h1"}, {"host": "h2"}])
    assert dds.discovery_server_value(r) == "10.0.0.1:11811;10.0.0.2:11811;10.0.0.3:11811"
    assert dds.server_environment(r, 1)["ROS_DISCOVERY_SERVER"] == "10.0.0.1:11811;10.0.0.3:11811"


def test_single_server_has_no_server_list_of_its_own() -> None:
    assert "ROS_DISCOVERY_SERVER" not in dds.server_environment(robot(), 0)


@given(count=st.integers(min_value=1, max_value=6), exclude=st.one_of(st.none(), st.integers(0, 5)))
def test_2x_position_is_server_id(count: int, exclude: int | None) -> None:
    r = robot("jazzy", servers=[{"host": f"h{i}", "port": 12000 + i} for i in range(count)], hosts=count)
    value = dds.discovery_server_value(r, exclude=exclude)
    if not value:  # the only server excluded
        assert count == 1 and exclude == 0
        return
    slots = value.split(";")
    for server in dds.servers(r):
        if server.index == exclude:
            assert server.index >= len(slots) or slots[server.index] == ""
        else:
            assert slots[server.index] == f"10.0.0.{server.index + 1}:{12000 + server.index}"
    assert slots[-1] != ""  # no trailing empty slot


@pytest.mark.parametrize("distro", ["humble", "jazzy", "kilted"])
def test_super_client_env_points_at_a_generated_profile(distro: str) -> None:
    r = robot(distro)
    env = dds.client_environment(r, super_client=True)
    assert env["ROS_SUPER_CLIENT"] == "TRUE"
    assert env["ROS_DISCOVERY_SERVER"] == dds.discovery_server_value(r)
    # 2.x reads FASTRTPS_*, 3.x reads FASTDDS_* (and warns about FASTRTPS_*, so it is not set there).
    path = env["FASTDDS_DEFAULT_PROFILES_FILE"]
    if r.fastdds_line == 2:
        assert env["FASTRTPS_DEFAULT_PROFILES_FILE"] == path
    else:
        assert "FASTRTPS_DEFAULT_PROFILES_FILE" not in env
    folder, name = path.rsplit("/", 1)
    assert folder == "/robocore/dds"
    assert name in dds.profile_files(r)


def test_udp_transport_settings() -> None:
    jazzy = robot("jazzy", transport="udp")
    assert dds.client_environment(jazzy)["FASTDDS_BUILTIN_TRANSPORTS"] == "UDPv4"
    assert parse(dds.client_xml(jazzy)).findtext(".//transport_descriptor/type") == "UDPv4"  # same as the variable
    assert "FASTDDS_BUILTIN_TRANSPORTS" not in dds.client_environment(robot("jazzy"))
    # Humble's Fast DDS 2.6 has no FASTDDS_BUILTIN_TRANSPORTS: a transport-only XML profile.
    humble = robot("humble", transport="udp")
    env = dds.client_environment(humble)
    assert env["FASTRTPS_DEFAULT_PROFILES_FILE"] == "/robocore/dds/client.xml"
    client = parse(dds.profile_files(humble)["client.xml"])
    assert client.find(".//useBuiltinTransports").text == "false"  # type: ignore[union-attr]
    assert client.find(".//transport_descriptor/type").text == "UDPv4"  # type: ignore[union-attr]
    # It must not set the discovery protocol, or ROS_DISCOVERY_SERVER would be ignored.
    assert client.find(".//discoveryProtocol") is None
    assert "FASTDDS_BUILTIN_TRANSPORTS" not in dds.client_environment(robot("humble"))


@pytest.mark.parametrize("distro", ["humble", "jazzy", "kilted"])
def test_shared_memory_profiles_keep_udp_and_check_ports_quickly(distro: str) -> None:
    r = robot(distro)
    assert r.discovery.transport == "shm"
    assert 0 < SHM_HEALTHY_CHECK_MS < 1000  # quicker than Fast DDS's default
    for name, xml in dds.profile_files(r).items():
        root = parse(xml)
        kinds = {d.findtext("transport_id"): d for d in root.iter("transport_descriptor")}
        assert [d.findtext("type") for d in kinds.values()] == ["SHM", "UDPv4"], name
        used = [t.text for t in root.find(".//userTransports")]  # type: ignore[union-attr]
        assert used == list(kinds), name  # both, as Fast DDS's builtin transports would be
        assert root.findtext(".//useBuiltinTransports") == "false"
        shm = next(d for d in kinds.values() if d.findtext("type") == "SHM")
        assert shm.findtext("healthy_check_timeout_ms") == str(SHM_HEALTHY_CHECK_MS)


@pytest.mark.parametrize("distro", ["humble", "jazzy", "kilted"])
def test_profiles_shorten_discovery_through_the_server(distro: str) -> None:
    r = robot(distro)
    for xml in (dds.client_xml(r), dds.super_client_xml(r)):
        config = parse(xml).find(".//discovery_config")
        assert config is not None
        period = config.find("clientAnnouncementPeriod/nanosec")
        assert period is not None and period.text == str(dds.CLIENT_ANNOUNCEMENT_MS * 1_000_000)
        assert config.findtext("initialAnnouncements/count") == str(dds.INITIAL_ANNOUNCEMENTS[0])
    # the plain client leaves the protocol to ROS_DISCOVERY_SERVER
    assert parse(dds.client_xml(r)).find(".//discoveryProtocol") is None
    server = parse(dds.server_profile_xml(r)).find(".//discovery_config")
    assert server is not None and server.findtext("discoveryProtocol") == "SERVER"
    assert server.findtext("clientAnnouncementPeriod/nanosec") == str(dds.SERVER_ANNOUNCEMENT_MS * 1_000_000)


@pytest.mark.parametrize("distro", ["humble", "jazzy", "kilted"])
@pytest.mark.parametrize("transport", ["shm", "udp"])
def test_clients_take_discovery_traffic_over_udp_at_their_usual_port(distro: str, transport: str) -> None:
    """Whatever carries the data, what servers and peers send a client for discovery arrives over UDP (a
    replaced node's shared-memory port may still be held by the server), at Fast DDS's own address and port."""
    r = robot(distro, transport=transport)
    for xml in (dds.client_xml(r), dds.super_client_xml(r)):
        builtin = parse(xml).find(".//participant/rtps/builtin")
        assert builtin is not None
        locators = builtin.findall("metatrafficUnicastLocatorList/locator")
        assert len(locators) == 1
        assert [child.tag for child in locators[0]] == ["udpv4"]
        udp = locators[0].find("udpv4")
        assert udp is not None and len(udp) == 0  # no address, no port: Fast DDS fills them in
        # data locators stay Fast DDS's own (shared memory on one host when the transport allows it)
        assert parse(xml).find(".//defaultUnicastLocatorList") is None
    # the server listens where its clients are told it is: its own profile is untouched
    assert parse(dds.server_profile_xml(r)).find(".//metatrafficUnicastLocatorList") is None


# ------------------------------------------------------------------ server argv


@pytest.mark.parametrize("distro", ["humble", "jazzy"])
def test_2x_server_command_has_its_id(distro: str) -> None:
    r = robot(distro, servers=[{"host": "h0"}, {"host": "h1", "port": 12345}])
    assert dds.server_command(r, 0) == ["fastdds", "discovery", "-i", "0", "-l", "0.0.0.0", "-p", "11811"]
    assert dds.server_command(r, 1) == ["fastdds", "discovery", "-i", "1", "-l", "0.0.0.0", "-p", "12345"]


def test_3x_server_command_has_no_id() -> None:
    r = robot("kilted", servers=[{"host": "h0", "port": 12000}])
    assert dds.server_command(r, 0) == ["fastdds", "discovery", "-l", "0.0.0.0", "-p", "12000"]


# ------------------------------------------------------------------ XML


@pytest.mark.parametrize("distro", ["humble", "jazzy"])
def test_2x_super_client_xml_lists_remote_servers_by_prefix(distro: str) -> None:
    r = robot(distro, servers=[{"host": "h0"}, {"host": "h1", "port": 12000}])
    root = parse(dds.super_client_xml(r))
    assert root.tag == "dds"
    participant = root.find("./profiles/participant")
    assert participant is not None and participant.get("is_default_profile") == "true"
    assert participant.find(".//discoveryProtocol").text == "SUPER_CLIENT"  # type: ignore[union-attr]
    remotes = participant.findall(".//discoveryServersList/RemoteServer")
    assert [r.get("prefix") for r in remotes] == [
        "44.53.00.5f.45.50.52.4f.53.49.4d.41",
        "44.53.01.5f.45.50.52.4f.53.49.4d.41",
    ]
    addresses = [(x.findtext(".//address"), x.findtext(".//port")) for x in remotes]
    assert addresses == [("10.0.0.1", "11811"), ("10.0.0.2", "12000")]
    assert "fastRTPS_Profiles" in dds.super_client_xml(r)


def test_3x_super_client_xml_lists_bare_locators() -> None:
    r = robot("kilted", servers=[{"host": "h0"}, {"host": "h2"}])
    text = dds.super_client_xml(r)
    root = parse(text)
    servers_list = root.find(".//discoveryServersList")
    assert servers_list is not None
    assert root.find(".//RemoteServer") is None
    assert [child.tag for child in servers_list] == ["locator", "locator"]
    assert [x.findtext(".//address") for x in servers_list] == ["10.0.0.1", "10.0.0.3"]
    assert 'xmlns="http://www.eprosima.com"' in text


def test_server_prefix_of_id_above_15_is_two_hex_digits() -> None:
    endpoint = dds.FastDdsServer(index=26, host="h", address="a", port=11811)
    assert endpoint.guid_prefix.split(".")[2] == "1a"


def test_udp_super_client_drops_builtin_transports() -> None:
    root = parse(dds.super_client_xml(robot("jazzy", transport="udp")))
    assert root.findtext(".//useBuiltinTransports") == "false"
    assert root.findtext(".//userTransports/transport_id") == root.findtext(".//transport_descriptor/transport_id")


def _seconds(element: ET.Element | None) -> float:
    """A Fast DDS duration element (``<sec>``, ``<nanosec>``) in seconds."""
    assert element is not None
    return int(element.findtext("sec") or 0) + int(element.findtext("nanosec") or 0) / 1e9


@pytest.mark.parametrize("distro", ["humble", "jazzy", "kilted"])
def test_server_profile_sets_its_lines_short_lease(distro: str) -> None:
    r = robot(distro)
    live = dds.server_liveliness(r)
    root = parse(dds.server_profile_xml(r))
    assert "\n" not in dds.server_profile_xml(r)  # one line: it travels in an environment variable
    assert root.findtext(".//discoveryProtocol") == "SERVER"
    assert _seconds(root.find(".//leaseDuration")) == live.lease_ms / 1000 < 20  # Fast DDS's own: 20 s
    # several announcements per lease: one lost packet does not drop the server
    assert _seconds(root.find(".//leaseAnnouncement")) * 3 <= live.lease_ms / 1000


def test_2x_keeps_its_8_s_lease_and_its_hold_outlasts_it() -> None:
    """2.x's settings are the measured ones (a shorter lease let matched nodes go unheard): 8 s announced every
    2 s, and a restarted server silent for longer than a lease."""
    for distro in ("humble", "jazzy"):
        live = dds.server_liveliness(robot(distro))
        assert (live.lease_ms, live.announcement_ms) == (8000, 2000)
        assert dds.restart_hold_seconds(robot(distro)) == live.hold_seconds > live.lease_ms / 1000
    assert "<leaseDuration><sec>8</sec></leaseDuration><leaseAnnouncement><sec>2</sec></leaseAnnouncement>" in \
        dds.server_profile_xml(robot("jazzy"))  # the text 2.x servers were measured with


def test_a_lease_of_a_fraction_of_a_second_keeps_its_fraction() -> None:
    half = dds.ServerLiveliness(lease_ms=2000, announcement_ms=500, hold_seconds=0)
    root = parse(dds.server_profile_xml(robot("kilted"), half))
    assert _seconds(root.find(".//leaseDuration")) == 2 and _seconds(root.find(".//leaseAnnouncement")) == 0.5


def test_3x_serves_at_once_after_a_restart_and_its_lease_bounds_the_recovery() -> None:
    """A 3.x server has a new GUID at each start: no hold. Its clients match the new one only once they dropped the
    killed one, so a node started after a restart is heard about a lease after the kill: under 5 s."""
    for distro in ("kilted", "rolling"):
        live = dds.server_liveliness(robot(distro))
        assert dds.restart_hold_seconds(robot(distro)) == live.hold_seconds == 0
        assert live.lease_ms <= 3000 and live.announcement_ms <= live.lease_ms // 3


def test_a_given_liveliness_replaces_the_lines_own() -> None:
    """The bench's contrast: 3.x's server with 2.x's lease."""
    lease_8s = dds.ServerLiveliness(lease_ms=8000, announcement_ms=2000, hold_seconds=0)
    root = parse(dds.server_profile_xml(robot("kilted"), lease_8s))
    assert _seconds(root.find(".//leaseDuration")) == 8 and _seconds(root.find(".//leaseAnnouncement")) == 2
    assert 'xmlns="http://www.eprosima.com"' in dds.server_profile_xml(robot("kilted"), lease_8s)


# ------------------------------------------------------------------ replacements


@pytest.mark.parametrize("distro", ["humble", "jazzy", "kilted"])
def test_a_replacements_profile_is_the_client_profile_with_other_user_ports(distro: str) -> None:
    files = dds.profile_files(robot(distro))
    first, *others = dds.CLIENT_ROTATION
    assert first == dds.CLIENT_PROFILE and len(others) >= 3
    offsets = [11]  # Fast DDS's own, where the client profile leaves it
    for name in others:
        offset = parse(files[name]).find(".//{*}rtps/{*}port/{*}offsetd3")
        assert offset is not None and offset.text is not None
        port = f"        <port><offsetd3>{offset.text}</offsetd3></port>\n"
        assert files[name].replace(port, "") == files[dds.CLIENT_PROFILE]  # nothing else differs
        offsets.append(int(offset.text))
    assert parse(files[dds.CLIENT_PROFILE]).find(".//{*}rtps/{*}port") is None
    assert all(o % 2 == 1 for o in offsets)  # discovery ports are even (10 + 2 x id): never met
    # participants 0-49 of one rotation step never take another step's port
    ports = [{o + 2 * pid for pid in range(50)} for o in offsets]
    assert all(not (a & b) for i, a in enumerate(ports) for b in ports[i + 1:])


@pytest.mark.parametrize("distro", ["jazzy", "kilted"])
def test_replacements_go_round_the_client_profiles(distro: str) -> None:
    planned = dds.client_environment(robot(distro))
    names = [n for n in dds.PROFILE_VARIABLES if n in planned]
    assert names
    env, seen = planned, []
    for _ in range(len(dds.CLIENT_ROTATION)):
        env = dds.successor_environment(env, planned)
        assert {k: v for k, v in env.items() if k not in names} == {k: v for k, v in planned.items() if k not in names}
        [file] = {env[n] for n in names}
        seen.append(file.rpartition("/")[2])
    assert seen == [*list(dds.CLIENT_ROTATION)[1:], dds.CLIENT_PROFILE]  # each once, then back to the start
    assert dds.successor_environment({}, planned) == planned  # a predecessor without a profile: as planned
    elsewhere = {n: "/elsewhere/client-1.xml" for n in names}  # another folder's file: not one of ours
    assert dds.successor_environment(elsewhere, planned) == planned


def test_a_super_client_is_never_given_the_successor_profile() -> None:
    planned = dds.client_environment(robot(), super_client=True)
    assert dds.successor_environment(planned, planned) == planned
