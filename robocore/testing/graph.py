"""``robot.graph``: the test process's own ROS 2 node, a super client of the run's discovery servers.

Every wait spins the node in the calling thread until its condition holds or its timeout passes,
so a test never races a background thread, and a failed wait fails the test with what was seen.
rclpy is imported here only, after :func:`robocore.testing.ros_env.prepare` set its environment.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import pytest

#: How long one spin waits for work before a condition is checked again.
SPIN_STEP = 0.05
#: After a publisher matched its first subscriber: how long it waits for the others the graph shows.
SETTLE = 1.0


def _qualified(name: str, namespace: str) -> str:
    return f"{namespace.rstrip('/')}/{name}"


class Graph:
    """An rclpy node in the test process that sees the robot's whole graph."""

    def __init__(self, name: str, domain_id: int) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor

        self._rclpy = rclpy
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._publishers: dict[tuple[str, type], Any] = {}
        self._clients: dict[tuple[str, type], Any] = {}

    # ------------------------------------------------------------------ what the graph holds

    def node_names(self) -> set[str]:
        """Fully qualified names of every node in the graph (``/talker``, ``/ns/name``), this one excepted."""
        own = self.node.get_fully_qualified_name()
        names = {_qualified(n, ns) for n, ns in self.node.get_node_names_and_namespaces()}
        return names - {own}

    def topic_names(self) -> dict[str, list[str]]:
        """Topic name -> its message types, for every topic in the graph."""
        return {name: list(types) for name, types in self.node.get_topic_names_and_types()}

    def spin(self, seconds: float) -> None:
        """Process callbacks for ``seconds``."""
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            self.executor.spin_once(timeout_sec=min(SPIN_STEP, left))

    def _until(self, condition: Callable[[], bool], timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while True:
            if condition():
                return True
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            self.executor.spin_once(timeout_sec=min(SPIN_STEP, left))

    def wait_for_node(self, name: str, timeout: float = 10.0) -> None:
        """Wait until node ``name`` (fully qualified) is in the graph; fail the test otherwise."""
        if not self._until(lambda: name in self.node_names(), timeout):
            pytest.fail(f"no node {name} in the graph within {timeout} s; nodes seen: "
                        f"{', '.join(sorted(self.node_names())) or 'none'}")

    def wait_for_topic(self, name: str, timeout: float = 10.0) -> None:
        """Wait until topic ``name`` is in the graph; fail the test otherwise."""
        topic = self._resolve(name)
        if not self._until(lambda: topic in self.topic_names(), timeout):
            pytest.fail(f"no topic {topic} in the graph within {timeout} s; topics seen: "
                        f"{', '.join(sorted(self.topic_names())) or 'none'}")

    # ------------------------------------------------------------------ messages

    def _resolve(self, topic: str) -> str:
        return str(self.node.resolve_topic_name(topic))

    def _publishers_seen(self, topic: str) -> list[Any]:
        return [p for p in self.node.get_publishers_info_by_topic(topic) if p.node_name != self.node.get_name()]

    def _subscription_qos(self, publishers: list[Any]) -> Any:
        """Reliable and transient-local when every publisher is, so that nothing they offer is refused."""
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        reliable = bool(publishers) and all(p.qos_profile.reliability == ReliabilityPolicy.RELIABLE
                                            for p in publishers)
        latched = bool(publishers) and all(p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
                                           for p in publishers)
        return QoSProfile(
            depth=10,
            reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
        )

    def wait_for_message(self, topic: str, msg_type: type, predicate: Callable[[Any], bool] | None = None,
                         timeout: float = 10.0) -> Any:
        """The first message on ``topic`` for which ``predicate`` holds (any message without one).

        Fails the test after ``timeout`` seconds, naming the topic, the publishers seen and the
        last message received.
        """
        topic = self._resolve(topic)
        deadline = time.monotonic() + timeout
        self._until(lambda: bool(self._publishers_seen(topic)), timeout)
        publishers = self._publishers_seen(topic)
        last: list[Any] = []
        found: list[Any] = []

        def received(msg: Any) -> None:
            last[:] = [msg]
            if not found and (predicate is None or predicate(msg)):
                found.append(msg)

        subscription = self.node.create_subscription(msg_type, topic, received, self._subscription_qos(publishers))
        try:
            self._until(lambda: bool(found), max(0.0, deadline - time.monotonic()))
        finally:
            self.node.destroy_subscription(subscription)
        if found:
            return found[0]
        seen = ", ".join(sorted({_qualified(p.node_name, p.node_namespace) for p in self._publishers_seen(topic)}))
        which = "matching the predicate " if predicate is not None else ""
        pytest.fail(f"no message {which}on {topic} ({msg_type.__name__}) within {timeout} s; "
                    f"publishers seen: {seen or 'none'}; last message received: {last[0] if last else 'none'}")

    def publish(self, topic: str, msg: Any, timeout: float = 10.0) -> None:
        """Publish ``msg`` on ``topic`` once a subscriber has matched, so that discovery timing loses nothing.

        The publisher is reliable and stays alive for the session. It waits for every subscriber
        the graph shows, for at most a second after the first one matched.
        """
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        topic = self._resolve(topic)
        key = (topic, type(msg))
        publisher = self._publishers.get(key)
        if publisher is None:
            qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
            publisher = self._publishers[key] = self.node.create_publisher(type(msg), topic, qos)
        first_match: list[float] = []

        def matched() -> bool:
            count = publisher.get_subscription_count()
            if count and not first_match:
                first_match.append(time.monotonic())
            others = sum(1 for s in self.node.get_subscriptions_info_by_topic(topic)
                         if s.node_name != self.node.get_name())
            return bool(count) and (count >= others or time.monotonic() - first_match[0] > SETTLE)

        if not self._until(matched, timeout):
            pytest.fail(f"nothing subscribed to {topic} within {timeout} s: the message was not published")
        publisher.publish(msg)

    def call(self, service: str, srv_type: type, request: Any, timeout: float = 10.0) -> Any:
        """Call ``service`` with ``request`` and return the response; fail the test after ``timeout`` seconds."""
        name = str(self.node.resolve_service_name(service))
        key = (name, srv_type)
        client = self._clients.get(key)
        if client is None:
            client = self._clients[key] = self.node.create_client(srv_type, name)
        deadline = time.monotonic() + timeout
        if not self._until(client.service_is_ready, timeout):
            pytest.fail(f"service {name} ({srv_type.__name__}) not available within {timeout} s")
        future = client.call_async(request)
        self._until(future.done, max(0.0, deadline - time.monotonic()))
        if not future.done():
            client.remove_pending_request(future)
            pytest.fail(f"service {name} did not answer within {timeout} s")
        return future.result()

    def describe(self) -> str:
        """The graph as text: nodes, then topics with their types (for failure reports)."""
        nodes = sorted(self.node_names())
        topics = self.topic_names()
        lines = [f"nodes ({len(nodes)}): {', '.join(nodes) or 'none'}", f"topics ({len(topics)}):"]
        lines += [f"  {name} [{', '.join(types)}]" for name, types in sorted(topics.items())]
        return "\n".join(lines)

    def close(self) -> None:
        """Destroy the node and shut its context down."""
        self.executor.shutdown()
        self.node.destroy_node()
        self._rclpy.try_shutdown(context=self.context)
