"""Graph tests: the talker and listener running in containers, seen from a ROS node in this process.

The `robot` fixture (robocore's pytest plugin, from robocore[testing]) builds what changed, starts
every component on this machine's Docker, isolated from other robots, and hands each test the
running robot: `robot.graph` is a ROS node in this process, `robot.logs`/`robot.wait_for_log`
read a component's output, `robot.restart` restarts one. Run them with `nox -s graph`.
"""

import time

from std_msgs.msg import String

GREETING = "hello from talker #"


def count(msg: String) -> int:
    """The N of a talker message "hello from talker #N" (-1 for any other text)."""
    prefix, _, number = msg.data.rpartition("#")
    return int(number) if prefix == GREETING[:-1] and number.isdigit() else -1


def heard(log: str, text: str) -> int:
    """How many lines of the listener's log say "I heard: <text>"."""
    return sum(line.rstrip().endswith(f"I heard: {text}") for line in log.splitlines())


def test_talker_and_listener_are_in_the_graph(robot):
    robot.graph.wait_for_node("/talker")
    robot.graph.wait_for_node("/listener")
    assert {"/talker", "/listener"} <= robot.graph.node_names()
    robot.graph.wait_for_topic("/chatter")


def test_talker_publishes_a_growing_count(robot):
    first = robot.graph.wait_for_message("/chatter", String, lambda m: count(m) > 0)
    later = robot.graph.wait_for_message("/chatter", String, lambda m: count(m) > count(first))
    assert later.data == f"{GREETING}{count(later)}"


def test_listener_hears_what_the_test_publishes(robot):
    robot.graph.publish("/chatter", String(data="hello from the graph test"))
    robot.wait_for_log("listener", "I heard: hello from the graph test")


def test_listener_keeps_hearing_after_the_talker_restarts(robot):
    # Past #5, the restarted talker (counting from #1 again) is told apart by a smaller count.
    before = count(robot.graph.wait_for_message("/chatter", String, lambda m: count(m) >= 5))
    log_before = robot.logs("listener")
    robot.restart("talker")
    again = robot.graph.wait_for_message("/chatter", String, lambda m: 0 < count(m) < before, timeout=20.0)
    # The listener printed this text at most once before the restart; it must print it again.
    times_before = heard(log_before, again.data)
    deadline = time.monotonic() + 10.0
    while heard(robot.logs("listener"), again.data) <= times_before:
        assert time.monotonic() < deadline, f"the listener did not hear {again.data!r} from the restarted talker"
        time.sleep(0.2)
