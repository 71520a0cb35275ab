"""Publish "hello from talker #N" on /chatter every 0.5 s."""

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from std_msgs.msg import String


def greeting(count: int) -> str:
    """The text of the ``count``-th message."""
    return f"hello from talker #{count}"


class Talker(Node):
    """A node that counts and publishes a greeting."""

    def __init__(self) -> None:
        super().__init__("talker")
        self.publisher = self.create_publisher(String, "chatter", 10)
        self.count = 0
        self.timer = self.create_timer(0.5, self.tick)

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
