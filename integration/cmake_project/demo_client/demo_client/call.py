"""`python3 -m demo_client.call SERVICE TIMEOUT`: one Greet call; exit 1 when no server answers in time."""

import sys

import rclpy
from demo_interfaces.srv import Greet


def main(argv: list[str]) -> int:
    """Call ``argv[0]`` with the name "once" and print the answer."""
    service, timeout = argv[0], float(argv[1])
    rclpy.init()
    node = rclpy.create_node("one_call")
    try:
        client = node.create_client(Greet, service)
        if not client.wait_for_service(timeout_sec=timeout):
            print(f"no service {service} within {timeout:g} s", flush=True)
            return 1
        future = client.call_async(Greet.Request(name="once"))
        rclpy.spin_until_future_complete(node, future, timeout_sec=timeout)
        if future.result() is None:
            print(f"no answer from {service} within {timeout:g} s", flush=True)
            return 1
        print(f"answer: {future.result().greeting}", flush=True)
        return 0
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
