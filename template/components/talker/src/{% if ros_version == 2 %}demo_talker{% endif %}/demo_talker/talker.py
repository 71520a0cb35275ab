"""Publish "hello from talker #N" on /chatter every 0.5 s, the first as soon as someone listens."""

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from std_msgs.msg import String

#: Seconds between two greetings.
PERIOD = 0.5
#: Seconds between two looks for a listener before the first greeting: a greeting sent before anyone listens is
#: lost, and one sent a whole period after start comes later than it needs to (a restarted talker is heard sooner).
FIRST_LOOK = 0.02
#: Seconds the first greeting waits for a listener at most. Discovery usually takes 0.1-0.3 s, on a busy machine
#: up to a second; a greeting sent on a shorter wait goes to nobody, and the listener hears the next one a whole
#: period later.
FIRST_WAIT = 2.0


def greeting(count: int) -> str:
    """The text of the ``count``-th message."""
    return f"hello from talker #{count}"


class Talker(Node):
    """A node that counts and publishes a greeting."""

    def __init__(self) -> None:
        super().__init__("talker")
        self.publisher = self.create_publisher(String, "chatter", 10)
        self.count = 0
        self.looks = 0
        self.timer = self.create_timer(FIRST_LOOK, self.first)

    def first(self) -> None:
        """Until a listener is there (at most FIRST_WAIT): look again; then greet, and every period after."""
        self.looks += 1
        if self.publisher.get_subscription_count() == 0 and self.looks * FIRST_LOOK < FIRST_WAIT:
            return
        self.destroy_timer(self.timer)
        self.tick()
        self.timer = self.create_timer(PERIOD, self.tick)

    def tick(self) -> None:
        """Publish the next greeting."""
        self.count += 1
        msg = String()
        msg.data = greeting(self.count)
        self.publisher.publish(msg)
        print(f"Publishing: {msg.data}", flush=True)


def main(args: list[str] | None = None) -> None:
    """Entry point of `ros2 run demo_talker talker`."""
    rclpy.init(args=args)
    node = Talker()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
