"""bench/discovery_traffic.py's pure parts: the robot it makes, the ports it counts, the counters it reads."""

from __future__ import annotations

from pathlib import Path
from types import ModuleType

import pytest
import yaml
from bench_scripts import load

from robocore.project import Project

TEMPLATE = {"ros_distro": "jazzy", "image_prefix": "traffic-", "base": {"kind": "wheels"},
            "hosts": [{"name": "main", "ip": "127.0.0.1"}],
            "components": [{"name": "talker", "folder": "components/talker", "runs_on": "main"}]}
#: What ``nft list counters table inet robocore_traffic`` prints (nftables 1.0.6, Debian 12).
NFT_OUTPUT = """table inet robocore_traffic {
\tcounter discovery {
\t\tpackets 1234 bytes 567890
\t}
\tcounter udp_all {
\t\tpackets 1300 bytes 600000
\t}
\tcounter tcp_all {
\t\tpackets 0 bytes 0
\t}
}
"""


@pytest.fixture(scope="module")
def bench() -> ModuleType:
    return load("discovery_traffic")


def test_nodes_are_spread_evenly_over_the_hosts_in_bounded_processes(bench: ModuleType) -> None:
    processes = bench.layout(64, 4, 8)
    assert [p.count for p in processes] == [8] * 8
    assert [p.host for p in processes] == ["h0", "h0", "h1", "h1", "h2", "h2", "h3", "h3"]
    assert [p.first for p in processes] == list(range(0, 64, 8))
    uneven = bench.layout(10, 4, 2)
    assert [(p.host, p.count) for p in uneven] == [("h0", 2), ("h0", 1), ("h1", 2), ("h1", 1), ("h2", 2), ("h3", 2)]
    assert sum(p.count for p in uneven) == 10
    with pytest.raises(ValueError):
        bench.layout(1, 2, 8)


def test_the_robot_is_a_valid_project_with_one_component_per_process(bench: ModuleType, tmp_path: Path) -> None:
    processes = bench.layout(8, 2, 8)
    data = bench.robot_yaml(TEMPLATE, processes, 2, 1)
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(data))
    (tmp_path / bench.SCRIPTS).mkdir()
    robot = Project.load(tmp_path).robot
    assert [h.name for h in robot.hosts] == ["h0", "h1"]
    assert [(c.name, c.runs_on) for c in robot.components] == [("nodes-0", "h0"), ("nodes-4", "h1")]
    assert str(robot.components[1].entrypoint).endswith("/robocore/dds/go 4 4 8")
    assert [(s.host, s.port) for s in robot.discovery_servers] == [("h0", 11811)]
    assert TEMPLATE["hosts"] == [{"name": "main", "ip": "127.0.0.1"}]  # the template is left alone


def test_discovery_ports_are_spdp_metatraffic_and_servers_never_user_data(bench: ModuleType) -> None:
    ports = bench.discovery_ports(0, [11811])
    assert {7400, 7410, 7412, 7410 + 2 * 119, 11811} <= set(ports)
    assert not {7401, 7411, 7413, 7511, 7611, 7711} & set(ports)  # user multicast, user unicast, rotations
    domain_5 = bench.discovery_ports(5, [12000])
    assert min(domain_5) == 7400 + 250 * 5 and 12000 in domain_5 and 7400 not in domain_5


def test_the_ruleset_counts_what_leaves_the_interface(bench: ModuleType) -> None:
    text = bench.nft_ruleset([7400, 7410, 11811])
    assert "table inet robocore_traffic" in text
    assert "elements = { 7400, 7410, 11811 }" in text
    assert 'oifname "eth0" udp dport @discovery_ports counter name "discovery"' in text
    assert "hook output" in text and "hook input" not in text
    assert all(f"counter {name} {{ }}" in text for name in ("discovery", "udp_all", "tcp_all"))


def test_counters_are_read_from_nft_output(bench: ModuleType) -> None:
    counts = bench.parse_counters(NFT_OUTPUT)
    assert counts == {"discovery": bench.Count(1234, 567890), "udp_all": bench.Count(1300, 600000),
                      "tcp_all": bench.Count(0, 0)}
    assert bench.parse_counters("table inet robocore_traffic {\n}\n") == {}


def test_seen_is_the_last_figure_up_to_the_mark(bench: ModuleType) -> None:
    log = "READY\nMADE 8 0.81\nSEEN 5 6\nSEEN 10 8\nSEEN 15 8\nSEEN 20 8\nSEEN 25 7\n"
    assert bench.seen_at(log, 20) == 8
    assert bench.seen_at(log, 7) == 6
    assert bench.seen_at(log, 80) == 7
    assert bench.seen_at("READY\nMADE 8 0.81\n", 20) is None


def test_the_wire_is_the_sum_over_hosts_and_later_is_per_minute(bench: ModuleType) -> None:
    point = bench.Point(nodes=8, hosts=2, mode="server", minutes=2.0)
    count = bench.Count
    point.first = {"h0": {"discovery": count(100, 1000)}, "h1": {"discovery": count(50, 500)}}
    point.later = {"h0": {"discovery": count(40, 400)}, "h1": {"discovery": count(20, 200)}}
    assert point.wire("discovery") == count(150, 1500)
    assert point.wire("discovery", later=True) == count(30, 300)
    assert bench.diff({"h0": {"discovery": count(9, 90)}}, {"h0": {"discovery": count(4, 40)}})["h0"] == {
        "discovery": count(5, 50), "udp_all": count(0, 0), "tcp_all": count(0, 0)}


def test_growth_is_per_node_added_from_one_size_to_the_next(bench: ModuleType) -> None:
    assert bench.growth({8: 80.0, 2: 20.0, 32: 500.0}) == [(2, 8, 10.0), (8, 32, 17.5)]
    assert bench.growth({2: 1.0}) == []


def test_the_ros_1_master_counts_tcp_and_runs_on_the_ros_1_project(bench: ModuleType) -> None:
    count = bench.Count
    point = bench.Point(nodes=2, hosts=2, mode="rosmaster", minutes=1.0)
    point.first = {"h0": {"discovery": count(0, 0), "udp_all": count(3, 300), "tcp_all": count(70, 9000)}}
    assert point.wire(point.discovery) == count(70, 9000)
    assert bench.Point(nodes=2, hosts=2, mode="simple", minutes=1.0).discovery == "discovery"
    assert [bench.ros_line(m) for m in bench.MODES] == ["ros2", "ros2", "ros1"]


def test_the_result_rows_carry_each_point_and_a_failed_one(bench: ModuleType) -> None:
    count = bench.Count
    good = bench.Point(nodes=8, hosts=2, mode="server", minutes=1.0, seen=(8, 8),
                       server={"cpu_first_s": 0.04, "cpu_per_min_s": 0.03, "rss_mib": 10.0})
    good.first = {"h0": {"discovery": count(645, 278 * 1024)}}
    good.later = {"h0": {"discovery": count(200, 132 * 1024)}}
    failed = bench.Point(nodes=64, hosts=4, mode="simple", minutes=1.0, error="RuntimeError: nodes-0 exited")
    rows = bench.figures_of([good, failed])
    assert [(r.label, r.value) for r in rows] == [
        ("8 nodes, 2 hosts, server: discovery packets, first 20 s", 645),
        ("8 nodes, 2 hosts, server: discovery packets per minute after", 200),
        ("8 nodes, 2 hosts, server: server CPU, first 20 s", 0.04),
        ("64 nodes, 4 hosts, simple", "failed")]
    assert "8 / 8 of 8" in rows[0].detail and "RSS 10.0 MiB" in rows[2].detail
