"""Call /greet once the service is there, print the answer, and print the first greetings heard."""

import rclpy
from demo_interfaces.msg import Greeting
from demo_interfaces.srv import Greet
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.task import Future

SHOWN = 5


class Caller(Node):
    """Subscribes to /greetings and calls /greet with its own name."""

    def __init__(self) -> None:
        super().__init__("caller")
        self.heard = 0
        self.pending: Future | None = None
        self.subscription = self.create_subscription(Greeting, "greetings", self.hear, 10)
        self.client = self.create_client(Greet, "greet")
        self.timer = self.create_timer(0.2, self.call)

    def hear(self, msg: Greeting) -> None:
        self.heard += 1
        if self.heard <= SHOWN:
            print(f"heard greeting #{msg.count}: {msg.text}", flush=True)

    def call(self) -> None:
        if self.pending is None and self.client.service_is_ready():
            self.pending = self.client.call_async(Greet.Request(name="client"))
            self.pending.add_done_callback(self.answered)

    def answered(self, future: Future) -> None:
        print(f"answer: {future.result().greeting}", flush=True)
        self.timer.cancel()


def main(args: list[str] | None = None) -> None:
    """Entry point of `ros2 run demo_client client`."""
    rclpy.init(args=args)
    node = Caller()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
