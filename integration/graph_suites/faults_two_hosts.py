"""Graph tests of a two-host robot under faults, run by integration/test_faults.py through the pytest plugin.

The robot: host ``main`` runs the talker (2 Hz, "hello from talker #N") and discovery server 0,
host ``arm`` runs the listener and discovery server 1. The test process (the probe) counts the
talker's messages; the listener's log says what it heard. Every fault is undone by the plugin
before the next test: the test after a deliberately failed one proves it. Figures go to stdout as
``FIGURE name value`` lines (the outer test prints them).

Every way a node comes back here is heard within ``BOUND`` (2 s): a host's boot (timed from the component's
start, as Docker records it), a node started while one server is down, and a node started while a restarted
server holds back (Fast DDS 2.x: 12 s silent after a restart) and the other serves.
"""

from __future__ import annotations

import itertools
import threading
import time
from typing import Any

import pytest
from rclpy.qos import qos_profile_sensor_data
from std_msgs.msg import String

from robocore.plan.starts import docker_epoch
from robocore.testing.faults import FaultError

GREETING = "hello from talker #"
#: Seconds within which a node that came back is heard (the goal is a median below 1 s on 2 cores; this bound
#: leaves room for a loaded CI machine).
BOUND = 2.0

#: Run in a component with ``robot.exec``: a new node publishing ``text i stamp payload`` on a topic
#: (reliable when there is no payload, best effort like a sensor stream when there is one).
PUBLISH = """
import sys, time, rclpy
from rclpy.qos import qos_profile_sensor_data
from std_msgs.msg import String
topic, text, count, period, size = sys.argv[1], sys.argv[2], int(sys.argv[3]), float(sys.argv[4]), int(sys.argv[5])
rclpy.init()
node = rclpy.create_node("pub_" + text.replace(" ", "_"))
pub = node.create_publisher(String, topic, qos_profile_sensor_data if size else 10)
print("created", time.time(), flush=True)
payload = "x" * size
for i in range(count):
    pub.publish(String(data=f"{text} {i} {time.time()} {payload}"))
    time.sleep(period)
"""


def count(msg: String) -> int:
    prefix, _, number = msg.data.rpartition("#")
    return int(number) if prefix == GREETING[:-1] and number.isdigit() else -1


def heard(robot: Any, text: str = "I heard: hello from talker #") -> int:
    return sum(text in line for line in robot.logs("listener").splitlines())


def figure(name: str, value: float) -> None:
    print(f"FIGURE {name} {value:.2f}", flush=True)


def started_at(robot: Any, service: str) -> float:
    """Epoch seconds of ``service``'s last start, as Docker recorded it."""
    return docker_epoch(robot.client.containers.get(robot.specs[service].name).attrs["State"]["StartedAt"])


def logged_since_start(robot: Any, service: str) -> str:
    """What ``service`` logged since its last start (Docker's timestamps)."""
    since = started_at(robot, service) - 0.001
    text = robot.client.containers.get(robot.specs[service].name).logs(timestamps=True).decode(errors="replace")
    return "\n".join(line for line in text.splitlines() if docker_epoch(line.split(" ", 1)[0]) >= since)


def listener_heard_since(robot: Any, since: float) -> float | None:
    """Epoch seconds of the listener's first greeting logged at or after ``since`` (Docker's timestamps)."""
    lines = robot.client.containers.get(robot.specs["listener"].name).logs(timestamps=True).decode(
        errors="replace").splitlines()
    stamps = [docker_epoch(line.split(" ", 1)[0]) for line in lines if "I heard: hello from talker #" in line]
    return min((stamp for stamp in stamps if stamp >= since), default=None)


def wall(monotonic: float) -> float:
    """Epoch seconds of a ``time.monotonic()`` reading of this process."""
    return time.time() - (time.monotonic() - monotonic)


class Topic:
    """Every message of one topic the probe receives: (arrival time, message)."""

    def __init__(self, robot: Any, topic: str, qos: Any = 100) -> None:
        self.seen: list[tuple[float, Any]] = []
        self.sub = robot.graph.node.create_subscription(String, topic, lambda m: self.seen.append(
            (time.monotonic(), m)), qos)

    def during(self, robot: Any, seconds: float) -> list[tuple[float, Any]]:
        mark = len(self.seen)
        robot.graph.spin(seconds)
        return self.seen[mark:]

    def until(self, robot: Any, check: Any, timeout: float) -> tuple[float, Any] | None:
        mark = len(self.seen)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            robot.graph.spin(0.05)
            for entry in self.seen[mark:]:
                if check(entry[1]):
                    return entry
        return None


@pytest.fixture(scope="module")
def chatter(robot: Any) -> Topic:
    topic = Topic(robot, "/chatter")
    assert topic.until(robot, lambda m: count(m) > 0, 20), "the probe never heard the talker"
    return topic


def in_background(robot: Any, component: str, argv: list[str]) -> threading.Thread:
    thread = threading.Thread(target=robot.exec, args=(component, argv), daemon=True)
    thread.start()
    return thread


def test_control_traffic_never_stops_without_a_fault(robot: Any, chatter: Topic) -> None:
    before = heard(robot)
    got = chatter.during(robot, 4.0)
    times = [t for t, _ in got]
    assert len(got) >= 6, got
    assert max(b - a for a, b in itertools.pairwise(times)) < 1.2, times
    assert heard(robot) - before >= 6


def test_a_cut_off_host_is_silent_until_reconnected(robot: Any, chatter: Topic) -> None:
    robot.faults.cut_off("main")
    robot.graph.spin(0.3)
    before = heard(robot)
    assert chatter.during(robot, 3.0) == [], "messages of a cut-off host arrived"
    assert heard(robot) == before, "the listener heard a cut-off host"
    assert robot.faults.describe() == ["host main cut off from the network"]
    robot.faults.reconnect("main")
    reconnected = time.monotonic()
    first = chatter.until(robot, lambda m: count(m) > 0, 10)
    assert first is not None, "no message after the reconnection"
    figure("reconnect_to_message_s", first[0] - reconnected)
    deadline = time.monotonic() + 10
    while heard(robot) == before:
        assert time.monotonic() < deadline, "the listener did not hear the talker again"
        robot.graph.spin(0.1)


def test_a_partition_splits_the_graph_each_half_works_and_they_merge(robot: Any, chatter: Topic) -> None:
    robot.graph.wait_for_node("/listener")
    robot.faults.partition(["main"], ["arm"])
    split = time.monotonic()
    robot.graph.spin(0.3)
    before = heard(robot)
    assert len(chatter.during(robot, 2.0)) >= 3, "the main half (talker and probe) stopped working"
    # the arm half: a node started there now is found through the arm's server and heard by the listener
    in_background(robot, "listener", ["python3", "-c", PUBLISH, "/chatter", "arm half", "40", "0.1", "0"])
    robot.wait_for_log("listener", "I heard: arm half", timeout=10)
    assert heard(robot) == before, "the listener heard the talker across the partition"
    deadline = time.monotonic() + 40
    while "/listener" in robot.graph.node_names():
        assert time.monotonic() < deadline, f"the probe still sees /listener: {robot.graph.node_names()}"
        robot.graph.spin(0.2)
    figure("partition_to_split_graph_s", time.monotonic() - split)
    robot.faults.heal()
    healed = time.monotonic()
    while heard(robot) == before:
        assert time.monotonic() < healed + 20, "the halves did not merge: the listener never heard the talker again"
        robot.graph.spin(0.1)
    figure("heal_to_merged_s", time.monotonic() - healed)
    # The test process's view of the graph: seen to miss /listener for over 20 s after healing in 2 of 6 runs
    # (Fast DDS 2.14: a super client that dropped server 1 during the partition), while data flowed. Reported only.
    deadline = time.monotonic() + 10
    while "/listener" not in robot.graph.node_names() and time.monotonic() < deadline:
        robot.graph.spin(0.2)
    if "/listener" in robot.graph.node_names():
        figure("heal_to_listener_in_graph_s", time.monotonic() - healed)
    else:
        print("NOTE the probe did not see /listener again within 10 s of the merge", flush=True)


def test_a_limited_link_slows_a_large_topic(robot: Any) -> None:
    """A node on host main publishes 1 kB at 200 Hz (200 kB/s; one frame each: larger messages are
    IP-fragmented, and a bottleneck that drops fragments lets almost no datagram through). Once the probe
    receives it: 3 s free, 4 s with main's link at 200 kbit/s (25 kB/s), 3 s free again."""
    bulk = Topic(robot, "/bulk", qos_profile_sensor_data)
    thread = in_background(robot, "talker", ["python3", "-c", PUBLISH, "/bulk", "bulk", "4000", "0.005", "1000"])
    assert bulk.until(robot, lambda m: True, 10) is not None, "nothing arrived on /bulk"

    def rate(seconds: float) -> float:
        return 1000 * len(bulk.during(robot, seconds)) / seconds

    free = rate(3.0)
    robot.faults.limit_link("main", rate_kbit=200)
    robot.graph.spin(0.5)
    limited = rate(4.0)
    robot.faults.unlimit_link("main")
    robot.graph.spin(0.5)
    again = rate(3.0)
    thread.join(timeout=30)
    figure("bulk_free_kBps", free / 1000)
    figure("bulk_limited_kBps", limited / 1000)
    figure("bulk_again_kBps", again / 1000)
    assert limited < free / 3 and limited < 1.5 * 200_000 / 8, (free, limited)
    assert again > 2 * limited, (free, limited, again)


def test_delay_is_refused_in_one_line_where_the_kernel_has_no_netem(robot: Any) -> None:
    with pytest.raises(FaultError, match="netem"):
        robot.faults.limit_link("arm", delay_ms=50)


def test_a_power_cut_kills_every_process_of_the_host_and_its_boot_restarts_them(robot: Any, chatter: Topic) -> None:
    killed = robot.faults.power_cut("arm")
    assert sorted(killed) == ["discovery-1", "listener"]
    for service in killed:
        state = robot.client.containers.get(robot.specs[service].name).attrs["State"]
        assert (state["Status"], state["ExitCode"]) == ("exited", 137), state
    assert len(chatter.during(robot, 1.0)) >= 1, "the other host stopped with it"
    before = heard(robot)
    booted_at = time.monotonic()
    assert robot.faults.boot("arm") == ["discovery-1", "listener"]
    while heard(robot) <= before:
        assert time.monotonic() < booted_at + 20, "the booted listener never heard the talker"
        time.sleep(0.1)
    figure("boot_to_heard_s", time.monotonic() - booted_at)
    since = started_at(robot, "listener")
    took = (listener_heard_since(robot, since) or float("inf")) - since
    figure("listener_start_to_heard_after_boot_s", took)
    assert took < BOUND, f"the booted listener heard the talker {took:.2f} s after its start"


def test_a_power_cut_of_the_talkers_host(robot: Any, chatter: Topic) -> None:
    robot.faults.power_cut("main")
    robot.graph.spin(0.3)
    assert chatter.during(robot, 1.0) == []
    booted_at = time.monotonic()
    robot.faults.boot("main")
    first = chatter.until(robot, lambda m: count(m) > 0, 20)
    assert first is not None, "the booted talker was never heard"
    figure("boot_to_probe_heard_s", first[0] - booted_at)
    since = started_at(robot, "talker")
    figure("talker_start_to_probe_heard_after_boot_s", wall(first[0]) - since)
    deadline = time.monotonic() + 20
    while not (heard_at := listener_heard_since(robot, since)):
        assert time.monotonic() < deadline, "the listener never heard the booted talker"
        robot.graph.spin(0.1)
    figure("talker_start_to_listener_heard_after_boot_s", heard_at - since)


def test_a_sigkilled_component_starts_again(robot: Any, chatter: Topic) -> None:
    robot.kill("talker")
    state = robot.client.containers.get(robot.specs["talker"].name).attrs["State"]
    assert state["ExitCode"] == 137, state
    assert robot.faults.describe() == ["component talker SIGKILLed"]
    robot.graph.spin(0.3)
    assert chatter.during(robot, 1.0) == []
    robot.start("talker")
    assert chatter.until(robot, lambda m: 0 < count(m) <= 3, 15) is not None
    assert robot.faults.describe() == []


def test_either_server_killed_loses_no_message_and_a_new_node_finds_its_peers(robot: Any, chatter: Topic) -> None:
    """The redundant pair: each discovery server SIGKILLed in turn for 6 s. The talker's sequence numbers at the
    probe have no gap across the outage, and a node started during it (on host main) is heard by the probe. The
    killed server is started again, and serves after its restart hold, before the other one is killed. It runs
    after the partition test: servers restarted before it change what the probe's view of the graph keeps."""
    late = Topic(robot, "/late")
    for index in (0, 1):
        server = f"discovery-{index}"
        # serving, and for a heartbeat since: a server killed during its own hold after the power cut above
        # never spoke again to its clients, which dropped it long ago, and its next start rightly holds nothing
        deadline = time.monotonic() + 20
        while "Server is running" not in logged_since_start(robot, server):
            assert time.monotonic() < deadline, f"{server} never served again after the power cut"
            robot.graph.spin(0.2)
        robot.graph.spin(1.5)
        mark = len(chatter.seen) - 1
        robot.kill(server)
        killed = time.monotonic()
        text = f"late{index}"
        in_background(robot, "talker", ["python3", "-c", PUBLISH, "/late", text, "80", "0.1", "0"])
        first = late.until(robot, lambda m, text=text: m.data.startswith(f"{text} "), 20)
        assert first is not None, f"a node started while {server} was down was never heard"
        figure(f"late_node_during_s{index}_outage_s", first[0] - killed)
        assert first[0] - killed < BOUND, f"a node started while {server} was down was heard late"
        robot.graph.spin(max(0.0, killed + 6.0 - time.monotonic()))
        numbers = [count(m) for _, m in chatter.seen[max(mark, 0):]]
        gaps = [(a, b) for a, b in itertools.pairwise(numbers) if b != a + 1]
        assert len(numbers) >= 10 and not gaps, f"talker messages lost while {server} was down: {gaps} {numbers}"
        robot.start(server)
        restarted = time.monotonic()
        # its restart hold (12 s on Fast DDS 2.x): a node started now is heard through the other server
        text = f"held{index}"
        in_background(robot, "talker", ["python3", "-c", PUBLISH, "/late", text, "80", "0.1", "0"])
        first = late.until(robot, lambda m, text=text: m.data.startswith(f"{text} "), 20)
        assert first is not None, f"a node started while {server} held back after its restart was never heard"
        assert "discovery server restarted" in logged_since_start(robot, server), f"{server} did not hold back"
        figure(f"late_node_during_s{index}_hold_s", first[0] - restarted)
        assert first[0] - restarted < BOUND, f"a node started while {server} held back was heard late"
        # the hold over (what was left of its 12 s since its last heartbeat: about 7 s after a 6 s outage) and the
        # server up again, then a few of its clients' pings: both serve again before the other one is killed
        deadline = restarted + 20
        while "Server is running" not in logged_since_start(robot, server):
            assert time.monotonic() < deadline, f"{server} never served again after its restart hold"
            robot.graph.spin(0.2)
        robot.graph.spin(3.0)
        figure(f"s{index}_restart_to_both_serving_s", time.monotonic() - restarted)
    assert robot.faults.describe() == []


def test_zz_a_failing_test_with_a_fault_in_force(robot: Any) -> None:
    robot.faults.cut_off("arm")
    robot.faults.limit_link("main", rate_kbit=1000, loss_percent=5)
    raise AssertionError("failing on purpose with faults in force")


def test_zzz_the_next_test_finds_every_fault_undone(robot: Any, chatter: Topic) -> None:
    assert robot.faults.describe() == []
    before = heard(robot)
    got = chatter.during(robot, 2.0)
    assert len(got) >= 3
    # the listener's host was cut off by the failed test: once undone, it re-matches the talker (a reconnected
    # host is heard again in about 1 s, up to several seconds on a loaded machine), so its log grows again
    deadline = time.monotonic() + 20.0
    while heard(robot) <= before and time.monotonic() < deadline:
        time.sleep(0.25)
    assert heard(robot) > before
