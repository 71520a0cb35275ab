"""Print every message heard on /chatter as "I heard: <text>"."""

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from std_msgs.msg import String


def heard_line(msg: String) -> str:
    """The line printed for a message heard on /chatter."""
    return f"I heard: {msg.data}"


class Listener(Node):
    """A node that prints what it hears."""

    def __init__(self) -> None:
        super().__init__("listener")
        self.subscription = self.create_subscription(String, "chatter", self.heard, 10)

    def heard(self, msg: String) -> None:
        """Print one message; flushed so that it shows in `docker logs` at once."""
        print(heard_line(msg), flush=True)


def main(args: list[str] | None = None) -> None:
    """Entry point of `ros2 run demo_listener listener`."""
    rclpy.init(args=args)
    node = Listener()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
