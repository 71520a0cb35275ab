"""Offer /greet (demo_interfaces/srv/Greet) and publish demo_interfaces/msg/Greeting on /greetings."""

import rclpy
from demo_interfaces.msg import Greeting
from demo_interfaces.srv import Greet
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node


class Greeter(Node):
    """Answers each Greet request and publishes a counted Greeting every 0.5 s."""

    def __init__(self) -> None:
        super().__init__("greeter")
        self.count = 0
        self.publisher = self.create_publisher(Greeting, "greetings", 10)
        self.service = self.create_service(Greet, "greet", self.greet)
        self.timer = self.create_timer(0.5, self.publish)

    def publish(self) -> None:
        self.count += 1
        self.publisher.publish(Greeting(text="hello from the greeter", count=self.count))

    def greet(self, request: Greet.Request, response: Greet.Response) -> Greet.Response:
        response.greeting = f"hello, {request.name}"
        print(f"greeted {request.name}", flush=True)
        return response


def main(args: list[str] | None = None) -> None:
    """Entry point of `ros2 run demo_server server`."""
    rclpy.init(args=args)
    node = Greeter()
    print("greeter ready", flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
