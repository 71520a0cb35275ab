"""Discovery traffic on the wire as a robot grows: Fast DDS discovery server (as robocore sets it up) vs simple
discovery, for 2, 8, 32 and 64 ROS 2 nodes on 2-4 hosts; and the discovery server's memory and CPU.

Each point is one robot brought up by the ``robot`` fixture's machinery (``robocore.testing.bring_up``): every
robot host is a network namespace of its own on one Docker bridge (the host containers of
:mod:`robocore.plan.testrun`), the discovery server runs as robocore runs it (one on the first host by
default), and the nodes run in components with robocore's own client environment and profiles. A node is an
rclpy node in an rclpy Context of its own, so each node is its own DDS participant, as when every node is its
own process; a component process holds up to ``--per-process`` of them (8). Each node publishes on one topic
and subscribes to the previous node's (a ring), beside ROS 2's own endpoints (rosout, parameter events,
parameter services, graph information). The nodes send no data. In ``simple`` mode no server runs and the
nodes drop robocore's discovery environment and profiles (Fast DDS's defaults: SPDP multicast, 3 s
announcements).

What is counted, per host network namespace: the UDP datagrams (and their IP bytes) the namespace sends out
of its one interface (``eth0``) to a discovery port: SPDP multicast (7400 + 250 x domain), the participants'
metatraffic unicast ports (that + 10 + 2 x participant id: SPDP and SEDP) and the discovery servers' ports
(11811). A datagram that IP fragments counts once. User-data ports (odd: + 11 + 2 x id, robocore's rotated
offsets 111/211/311, multicast + 1) are not discovery; they are counted apart as "other UDP" (with no data
sent, that is ROS 2's graph topic ``ros_discovery_info``, which goes over DDS user data, and the
acknowledgements of the rosout and parameter event writers). Traffic between processes of one host (loopback,
shared memory) never reaches the wire and is not counted. The wire total is the sum over the namespaces:
every datagram is counted once, where it was sent (a multicast datagram once, whatever number of hosts
receive it). Counters are an nftables table in each host's namespace, set by a container in that namespace
(the fault agent's image, :func:`robocore.testing.faults.agent_image`), zeroed just before the nodes start.

Windows: the first 20 s after the nodes are told to start (their processes were started and imported rclpy
before), then ``--minutes`` minutes, given per minute. Each node process prints how many nodes each of its
nodes sees (``seen``: the smallest, out of the robot's total) every 5 s.

    python bench/discovery_traffic.py [--nodes 2 8 32 64] [--modes server simple rosmaster] [--minutes 1]
        [--project DIR] [--ros1-project DIR]

The ROS 2 robot is made from ``robocore init --defaults --base wheels`` (Jazzy, Debian 12 + ROS 2 wheels), the
ROS 1 robot (``rosmaster``: the ROS master on h0, rospy nodes one per process, every TCP packet counted) from
``robocore init --defaults --distro noetic --base debian``, unless ``--project`` / ``--ros1-project`` names such a
project; their bases are built on first use and kept. Everything a point starts is removed before the next
point. Results and what they mean: docs/discovery-traffic.md.
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import math
import os
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from harness import Figure, copy_built_project, record

#: The script of a ROS 2 component: waits for the go file (it holds the mode first), then makes its nodes, each in a
#: context of its own (a DDS participant of its own); every 5 s, how many nodes the least informed of them sees.
NODES = """
import os, sys, time
go, first, count, total = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
import rclpy
from rclpy.context import Context
from std_msgs.msg import String
print("READY", flush=True)
while not os.path.exists(go):
    time.sleep(0.02)
if open(go).read().split()[0] == "simple":  # Fast DDS's defaults: no server, no robocore profile
    for name in ("ROS_DISCOVERY_SERVER", "ROS_SUPER_CLIENT", "FASTDDS_DEFAULT_PROFILES_FILE",
                 "FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_BUILTIN_TRANSPORTS"):
        os.environ.pop(name, None)
start = time.monotonic()
nodes = []
for i in range(first, first + count):
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node(f"bench_n{i}", context=context)
    node.create_publisher(String, f"bench/t{i}", 10)
    node.create_subscription(String, f"bench/t{(i - 1) % total}", lambda _: None, 10)
    nodes.append(node)
print(f"MADE {count} {time.monotonic() - start:.2f}", flush=True)
tick = 0
while True:
    tick += 5
    time.sleep(max(0.0, start + tick - time.monotonic()))
    print(f"SEEN {tick} {min(len(n.get_node_names()) for n in nodes)}", flush=True)
"""
#: A ROS 1 node (rospy: one node per process), started by :data:`NODES_ROS1`.
NODE_ROS1 = """
import sys, rospy
from std_msgs.msg import String
i, total = int(sys.argv[1]), int(sys.argv[2])
rospy.init_node(f"bench_n{i}", disable_signals=True)
rospy.Publisher(f"/bench/t{i}", String, queue_size=10)
rospy.Subscriber(f"/bench/t{(i - 1) % total}", String, lambda _: None)
rospy.spin()
"""
#: The script of a ROS 1 component: waits for the go file (mode, end of the window in s), then starts its nodes;
#: how many bench nodes the master knows, 2 s before the end of the first window and 1 s after the last (one call
#: each: it is traffic too, and the last falls after the counters are read).
NODES_ROS1 = """
import os, subprocess, sys, time
go, first, count, total = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
import rosgraph, rospy
print("READY", flush=True)
while not os.path.exists(go):
    time.sleep(0.02)
end = float(open(go).read().split()[1])
start = time.monotonic()
node = os.path.join(os.path.dirname(os.path.abspath(__file__)), "bench_node_ros1.py")
children = [subprocess.Popen([sys.executable, node, str(i), str(total)]) for i in range(first, first + count)]
print(f"MADE {count} {time.monotonic() - start:.2f}", flush=True)
for mark in (18, end + 1):
    time.sleep(max(0.0, start + mark - time.monotonic()))
    state = rosgraph.Master("/bench_count").getSystemState()
    names = {n for _, nodes in state[0] for n in nodes if n.startswith("/bench_n")}
    print(f"SEEN {mark:.0f} {len(names)}", flush=True)
time.sleep(3600)
"""
#: The scripts' folder in the bench project, mounted at the same path in the node containers.
SCRIPTS = "bench"
SCRIPT_FILE = "bench_nodes.py"
GO_FILE = "go"
FIRST_WINDOW_S = 20.0
AFTER_END_S = 3.0
#: Participant ids whose metatraffic ports are counted (per host; Fast DDS gives them out from 0).
PARTICIPANT_IDS = 120
TABLE = "robocore_traffic"
INTERFACE = "eth0"
COUNTERS = ("discovery", "udp_all", "tcp_all")
MODES = ("server", "simple", "rosmaster")


# --------------------------------------------------------------------------- pure: the robot, ports, counters


@dataclass(frozen=True)
class Process:
    """One component process: its host, and the global indexes of its nodes."""

    host: str
    first: int
    count: int

    @property
    def name(self) -> str:
        """The component's name."""
        return f"nodes-{self.first}"


def host_count(nodes: int) -> int:
    """Hosts of a point by default: 2 up to 8 nodes, else 4."""
    return 2 if nodes <= 8 else 4


def layout(nodes: int, hosts: int, per_process: int) -> list[Process]:
    """``nodes`` spread evenly over ``hosts`` (h0, h1...), in processes of at most ``per_process`` nodes."""
    if nodes < hosts:
        raise ValueError(f"{nodes} nodes cannot cover {hosts} hosts")
    out, first = [], 0
    for index in range(hosts):
        on_host = nodes // hosts + (1 if index < nodes % hosts else 0)
        while on_host:
            count = min(per_process, on_host)
            out.append(Process(f"h{index}", first, count))
            first, on_host = first + count, on_host - count
    return out


def robot_yaml(template: dict[str, Any], processes: Sequence[Process], hosts: int, servers: int) -> dict[str, Any]:
    """The template project's robot.yaml with ``hosts`` hosts, one component per process, ``servers`` servers."""
    first = dict(template["hosts"][0])
    first.update(user="root")
    data = dict(template)
    data["hosts"] = [{**first, "name": f"h{i}", "ip": f"192.0.2.{10 + i}"} for i in range(hosts)]
    total = sum(p.count for p in processes)
    data["components"] = [
        {"name": p.name, "runs_on": p.host, "volumes": [f"./{SCRIPTS}:/{SCRIPTS}:ro"],
         "entrypoint": f"python3 /{SCRIPTS}/{SCRIPT_FILE} /robocore/dds/{GO_FILE} {p.first} {p.count} {total}"}
        for p in processes]
    data["discovery"] = {"servers": [{"host": f"h{i}"} for i in range(servers)]}
    return data


def discovery_ports(domain: int, server_ports: Iterable[int]) -> list[int]:
    """UDP ports that carry discovery in ``domain``: SPDP multicast, each participant id's metatraffic unicast
    port (RTPS's well-known ports: 7400 + 250 x domain, + 10 + 2 x id) and the servers' ports."""
    base = 7400 + 250 * domain
    return sorted({base, *(base + 10 + 2 * pid for pid in range(PARTICIPANT_IDS)), *server_ports})


def nft_ruleset(ports: Sequence[int], interface: str = INTERFACE) -> str:
    """An nftables table counting what the namespace sends out of ``interface``: datagrams to ``ports``, all UDP,
    all TCP (named counters, read by :func:`parse_counters`)."""
    elements = ", ".join(str(p) for p in ports)
    return (
        f"table inet {TABLE} {{\n"
        f"  set discovery_ports {{ type inet_service; elements = {{ {elements} }} }}\n"
        + "".join(f"  counter {name} {{ }}\n" for name in COUNTERS)
        + "  chain out {\n"
        "    type filter hook output priority -300; policy accept;\n"
        f'    oifname "{interface}" udp dport @discovery_ports counter name "discovery"\n'
        f'    oifname "{interface}" meta l4proto udp counter name "udp_all"\n'
        f'    oifname "{interface}" meta l4proto tcp counter name "tcp_all"\n'
        "  }\n"
        "}\n"
    )


@dataclass(frozen=True)
class Count:
    """Packets and bytes of one counter."""

    packets: int = 0
    bytes: int = 0

    def __add__(self, other: Count) -> Count:
        return Count(self.packets + other.packets, self.bytes + other.bytes)

    def __sub__(self, other: Count) -> Count:
        return Count(self.packets - other.packets, self.bytes - other.bytes)


_COUNTER = re.compile(r"counter\s+(\w+)\s*\{\s*packets\s+(\d+)\s+bytes\s+(\d+)", re.S)


def parse_counters(text: str) -> dict[str, Count]:
    """``nft list counters table inet TABLE``'s output: counter name -> its count."""
    return {m[1]: Count(int(m[2]), int(m[3])) for m in _COUNTER.finditer(text)}


_SEEN = re.compile(r"^SEEN (\d+) (\d+)\s*$", re.M)


def seen_at(log: str, second: float) -> int | None:
    """The last ``SEEN`` figure a node process printed at or before ``second`` s (None: none yet)."""
    seen = [(int(t), int(n)) for t, n in _SEEN.findall(log) if int(t) <= second]
    return seen[-1][1] if seen else None


def growth(points: dict[int, float]) -> list[tuple[int, int, float]]:
    """The growth of a figure per added node between each size and the next: (from, to, per node)."""
    sizes = sorted(points)
    return [(a, b, (points[b] - points[a]) / (b - a)) for a, b in itertools.pairwise(sizes)]


# --------------------------------------------------------------------------- a point on the local daemon


@dataclass
class Point:
    """What one robot (nodes, hosts, mode) put on the wire, and what its server and nodes used."""

    nodes: int
    hosts: int
    mode: str
    minutes: float
    first: dict[str, dict[str, Count]] = field(default_factory=dict)  # host -> counter -> the first 20 s
    later: dict[str, dict[str, Count]] = field(default_factory=dict)  # host -> counter -> the minutes after
    seen: tuple[int | None, int | None] = (None, None)  # smallest node count seen at 20 s, at the end
    server: dict[str, float] = field(default_factory=dict)  # cpu_first_s, cpu_per_min_s, rss_mib
    node_rss_mib: float = math.nan  # memory of the node processes' containers, per node
    error: str = ""

    @property
    def discovery(self) -> str:
        """The counter of this mode's discovery traffic: ROS 1's is TCP (XML-RPC with the master and between
        the nodes, TCPROS connection set-up: the nodes send no data)."""
        return "tcp_all" if self.mode == "rosmaster" else "discovery"

    def wire(self, counter: str, *, later: bool = False) -> Count:
        """The sum over the hosts of ``counter`` in the first window (or the later one, per minute)."""
        window = self.later if later else self.first
        total = sum((c[counter] for c in window.values()), Count())
        return Count(round(total.packets / self.minutes), round(total.bytes / self.minutes)) if later else total


class Counters:
    """An nftables counting table in each host namespace of a run, set by a container of its own there."""

    def __init__(self, robot: Any, ports: Sequence[int]) -> None:
        from robocore.plan import faults as fault_plan
        from robocore.plan import testrun
        from robocore.testing.faults import agent_image

        self.robot = robot
        run = robot.run
        hosts = testrun.hosts_to_start(robot.project.robot)
        image = agent_image(robot.client, testrun.host_spec(run, robot.project, hosts[0]).image)
        self.agents: dict[str, Any] = {}
        try:
            for host in hosts:
                self.agents[host] = robot.client.containers.run(
                    image, entrypoint=["sleep"], command=["infinity"], name=f"{run.prefix}-traffic-{host}",
                    network_mode=f"container:{run.host_container(host)}", cap_add=["NET_ADMIN"], labels=run.labels,
                    detach=True, user="root")
                self._exec(host, ["sh", "-c", fault_plan.NFT_SCRIPT, "robocore-nft", nft_ruleset(ports)])
        except BaseException:
            self.close()
            raise

    def _exec(self, host: str, argv: list[str]) -> str:
        code, output = self.agents[host].exec_run(argv)
        text = output.decode(errors="replace")
        if code != 0:
            raise RuntimeError(f"{host}: {argv[0]} exited {code}: {text[-400:]}")
        return str(text)

    def reset(self) -> None:
        """Zero every counter."""
        for host in self.agents:
            self._exec(host, ["nft", "reset", "counters", "table", "inet", TABLE])

    def read(self) -> dict[str, dict[str, Count]]:
        """host -> counter -> its count now."""
        return {host: parse_counters(self._exec(host, ["nft", "list", "counters", "table", "inet", TABLE]))
                for host in self.agents}

    def close(self) -> None:
        """Remove the counting containers (the table goes with the namespace)."""
        for agent in self.agents.values():
            with contextlib.suppress(Exception):
                agent.remove(force=True)


def usage(container: Any) -> tuple[float, float]:
    """(CPU seconds used so far, resident memory in MiB) of a container (cgroup v1 or v2 figures)."""
    stats = container.stats(stream=False, one_shot=True)
    cpu = stats["cpu_stats"]["cpu_usage"]["total_usage"] / 1e9
    memory = stats.get("memory_stats", {}).get("stats", {})
    rss = memory.get("total_rss", memory.get("rss", memory.get("anon", 0)))
    return cpu, rss / 2**20


def diff(after: dict[str, dict[str, Count]], before: dict[str, dict[str, Count]]) -> dict[str, dict[str, Count]]:
    return {h: {c: after[h].get(c, Count()) - before[h].get(c, Count()) for c in COUNTERS} for h in after}


def wait_ready(robot: Any, components: Sequence[str], timeout: float = 120) -> None:
    """Wait until every node process has imported rclpy (so that the window counts discovery, not imports)."""
    deadline = time.monotonic() + timeout
    while not all("READY" in robot.logs(c) for c in components):
        if time.monotonic() > deadline:
            raise RuntimeError(f"the node processes were not ready within {timeout:.0f} s")
        time.sleep(0.2)


def measure(project: Path, point: Point, servers: int, per_process: int) -> Point:
    """Bring the point's robot up, count, take it down."""
    from robocore.testing import bring_up

    template = yaml.safe_load((project / "robot.template.yaml").read_text())
    processes = layout(point.nodes, point.hosts, per_process)
    (project / "robot.yaml").write_text(yaml.safe_dump(robot_yaml(template, processes, point.hosts, servers),
                                                       sort_keys=False))
    robot = bring_up(project, servers=point.mode != "simple", graph=False)
    counters = None
    try:
        domain = robot.project.robot.ros_domain_id
        ports = [robot.project.robot.server_port(s) for s in robot.project.robot.discovery_servers]
        counters = Counters(robot, discovery_ports(domain, ports))
        server = robot.containers["discovery-0"].get_wrapped_container() if point.mode != "simple" else None
        wait_ready(robot, [p.name for p in processes])
        counters.reset()
        cpu0 = usage(server)[0] if server is not None else 0.0
        go = robot.run_dir / "dds" / GO_FILE
        go.write_text(f"{point.mode} {FIRST_WINDOW_S + 60 * point.minutes:.0f}\n")
        start = time.monotonic()
        time.sleep(max(0.0, start + FIRST_WINDOW_S - time.monotonic()))
        at_first = counters.read()
        cpu1 = usage(server)[0] if server is not None else 0.0
        time.sleep(max(0.0, start + FIRST_WINDOW_S + 60 * point.minutes - time.monotonic()))
        at_end = counters.read()
        time.sleep(AFTER_END_S)  # the last SEEN lines (ROS 1's comes after the counters are read)
        if server is not None:
            cpu2, rss = usage(server)
            point.server = {"cpu_first_s": cpu1 - cpu0, "cpu_per_min_s": (cpu2 - cpu1) / point.minutes,
                            "rss_mib": rss}
        point.first = diff(at_first, {h: {} for h in at_first})
        point.later = diff(at_end, at_first)
        for process in processes:  # a node process that died would read as a quiet one
            container = robot.containers[process.name].get_wrapped_container()
            container.reload()
            if container.status != "running":
                tail = robot.logs(process.name).strip().splitlines()[-1:] or ["no output"]
                raise RuntimeError(f"{process.name} on {process.host} exited "
                                   f"({container.attrs['State'].get('ExitCode')}): {tail[0][:200]}")
        logs = [robot.logs(p.name) for p in processes]
        firsts = [seen_at(log, FIRST_WINDOW_S) for log in logs]
        lasts = [seen_at(log, FIRST_WINDOW_S + 60 * point.minutes + AFTER_END_S) for log in logs]
        point.seen = (None if None in firsts else min(f for f in firsts if f is not None),
                      None if None in lasts else min(f for f in lasts if f is not None))
        rss = sum(usage(robot.containers[p.name].get_wrapped_container())[1] for p in processes)
        point.node_rss_mib = rss / point.nodes
    finally:
        if counters is not None:
            counters.close()
        robot.close()
    return point


#: The template each mode's robot is made from: ``robocore init`` arguments, the folder name (fixed, so that the
#: images, the base built on first use, are found again by the next run) and the scripts of its node processes.
PROJECTS = {
    "ros2": (("--base", "wheels"), "discovery-traffic", {SCRIPT_FILE: NODES}),
    "ros1": (("--distro", "noetic", "--base", "debian"), "discovery-traffic-ros1",
             {SCRIPT_FILE: NODES_ROS1, "bench_node_ros1.py": NODE_ROS1}),
}


def ros_line(mode: str) -> str:
    """The project a mode runs on."""
    return "ros1" if mode == "rosmaster" else "ros2"


@contextlib.contextmanager
def bench_project(line: str, given: Path | None) -> Iterator[Path]:
    """A copy of the template project (``given``, else a new one from ``robocore init --defaults``) with the
    node scripts, and its robot.yaml kept as robot.template.yaml."""
    init, name, scripts = PROJECTS[line]
    with tempfile.TemporaryDirectory(prefix="robocore-bench-traffic-") as scratch:
        root = Path(scratch) / name
        if given is None:
            subprocess.run([sys.executable, "-m", "robocore", "init", str(root), "--defaults", *init],
                           check=True, capture_output=True)
        else:
            copy_built_project(given, root)  # into a new folder: nothing of it to delete
        (root / "robot.template.yaml").write_text((root / "robot.yaml").read_text())
        (root / SCRIPTS).mkdir()
        os.chmod(root / SCRIPTS, 0o755)
        for file, text in scripts.items():
            (root / SCRIPTS / file).write_text(text)
            os.chmod(root / SCRIPTS / file, 0o644)
        yield root


# --------------------------------------------------------------------------- the table


def show(count: Count) -> str:
    return f"{count.packets:,} / {count.bytes / 1024:,.0f} KiB"


def ratio(simple: Point, server: Point) -> float:
    """Discovery packets of simple discovery per packet of the server's, in the first 20 s."""
    return simple.wire(simple.discovery).packets / max(server.wire(server.discovery).packets, 1)


def report(points: list[Point], servers: int) -> None:
    """The table, the growth per node, the server's and the nodes' memory and CPU."""
    print(f"\nDiscovery sent on the wire (the sum over the host namespaces), packets / KiB of IP; {servers} "
          "server(s) on h0 (server mode; rosmaster: the ROS master on h0, and every TCP packet counts)")
    print("| nodes | hosts | mode | discovery, first 20 s | discovery per minute after | other UDP, first 20 s "
          "| busiest host, first 20 s | seen at 20 s / end |")
    print("|---|---|---|---|---|---|---|---|")
    for p in points:
        if p.error:
            print(f"| {p.nodes} | {p.hosts} | {p.mode} | failed: {p.error} | | | | |")
            continue
        other = show(p.wire("udp_all") - p.wire("discovery")) if p.discovery == "discovery" else "-"
        busiest = max(p.first, key=lambda h: p.first[h][p.discovery].packets)
        share = p.first[busiest][p.discovery].packets / max(p.wire(p.discovery).packets, 1)
        seen = " / ".join("-" if s is None else str(s) for s in p.seen)
        print(f"| {p.nodes} | {p.hosts} | {p.mode} | {show(p.wire(p.discovery))} | "
              f"{show(p.wire(p.discovery, later=True))} | {other} | {busiest} {share:.0%} | {seen} of {p.nodes} |")
    good = [p for p in points if not p.error]
    print("\nDiscovery packets per node, and per node added from one size to the next:")
    for mode in sorted({p.mode for p in good}):
        mine = sorted((p for p in good if p.mode == mode), key=lambda p: p.nodes)
        for label, later in (("first 20 s", False), ("per minute after", True)):
            figures = {p.nodes: float(p.wire(p.discovery, later=later).packets) for p in mine}
            each = ", ".join(f"{n}: {v / n:,.0f}" for n, v in figures.items())
            added = ", ".join(f"{a}->{b}: {v:,.0f}" for a, b, v in growth(figures))
            print(f"  {mode:9} {label:17} per node {each}; per added node {added}")
    by = {(p.nodes, p.mode): p for p in good}
    ratios = [f"{n} nodes {ratio(by[(n, 'simple')], by[(n, 'server')]):.1f}x"
              for n in sorted({p.nodes for p in good}) if (n, "simple") in by and (n, "server") in by]
    if ratios:
        print("simple / server, discovery packets in the first 20 s: " + ", ".join(ratios))
    print("\n| nodes | mode | server CPU s, first 20 s | server CPU s per minute after | server RSS MiB "
          "| node containers' RSS per node, MiB |")
    print("|---|---|---|---|---|---|")
    for p in good:
        s = p.server
        cells = [f"{s['cpu_first_s']:.2f}", f"{s['cpu_per_min_s']:.2f}", f"{s['rss_mib']:.1f}"] if s else ["-"] * 3
        print(f"| {p.nodes} | {p.mode} | {' | '.join(cells)} | {p.node_rss_mib:.1f} |")


def figures_of(points: list[Point]) -> list[Figure]:
    """The result file's rows: each point's discovery packets (first 20 s, per minute after) and the server's cost."""
    out = []
    for p in points:
        name = f"{p.nodes} nodes, {p.hosts} hosts, {p.mode}"
        if p.error:
            out.append(Figure(name, "failed", detail=p.error))
            continue
        seen = " / ".join("-" if s is None else str(s) for s in p.seen)
        first, later = p.wire(p.discovery), p.wire(p.discovery, later=True)
        out.append(Figure(f"{name}: discovery packets, first 20 s", first.packets, "packets",
                          detail=f"{first.bytes / 1024:,.0f} KiB; nodes seen at 20 s / end: {seen} of {p.nodes}"))
        out.append(Figure(f"{name}: discovery packets per minute after", later.packets, "packets",
                          detail=f"{later.bytes / 1024:,.0f} KiB"))
        if p.server:
            out.append(Figure(f"{name}: server CPU, first 20 s", p.server["cpu_first_s"], "s",
                              detail=f"{p.server['cpu_per_min_s']:.2f} s per minute after; "
                                     f"RSS {p.server['rss_mib']:.1f} MiB"))
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--nodes", type=int, nargs="+", default=[2, 8, 32, 64])
    parser.add_argument("--hosts", type=int, help="hosts of every point (default: 2 up to 8 nodes, else 4)")
    parser.add_argument("--modes", nargs="+", choices=MODES, default=list(MODES))
    parser.add_argument("--minutes", type=float, default=1.0, help="the window after the first 20 s")
    parser.add_argument("--servers", type=int, default=1, help="discovery servers (on h0, h1...)")
    parser.add_argument("--per-process", type=int, default=8, help="nodes per component process")
    parser.add_argument("--project", type=Path, help="a jazzy template project on the wheels base (default: new)")
    parser.add_argument("--ros1-project", type=Path, help="a noetic template project on the debian base")
    args = parser.parse_args()
    print(f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}; {args.minutes:g} min after the first "
          f"{FIRST_WINDOW_S:.0f} s; {args.per_process} nodes per process", flush=True)
    points = []
    given = {"ros2": args.project, "ros1": args.ros1_project}
    with contextlib.ExitStack() as stack:
        projects = {line: stack.enter_context(bench_project(line, given[line]))
                    for line in sorted({ros_line(m) for m in args.modes})}
        for nodes in args.nodes:
            for mode in args.modes:
                point = Point(nodes, args.hosts or host_count(nodes), mode, args.minutes)
                began = time.monotonic()
                try:
                    measure(projects[ros_line(mode)], point, args.servers, args.per_process)
                except Exception as error:  # a failed point is reported in the table, the others still run
                    point.error = f"{type(error).__name__}: {str(error).splitlines()[0][:200]}"
                figure = point.error or show(point.wire(point.discovery))
                print(f"{nodes} nodes, {point.hosts} hosts, {mode}: {figure} ({time.monotonic() - began:.0f} s)",
                      flush=True)
                points.append(point)
    report(points, args.servers)
    record("discovery_traffic", figures_of(points),
           notes=[f"discovery datagrams sent on the wire, summed over the host namespaces; {args.servers} server(s); "
                  f"{args.per_process} nodes per process; docs/discovery-traffic.md"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
