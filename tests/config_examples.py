"""robot.yaml examples written as a user meets them, in fragments, and the whole documents built from them.

The fragments are top-level keys, hosts, common packages and components (a micro-ROS agent, a VNC desktop on the
robot or on the dev machine, a moveit planner, Jetsons). A fragment that has no top-level section is completed
with the top-level fragment; the fragment text itself is never changed.
"""

from __future__ import annotations

from dataclasses import dataclass

TOP = """\
ros_distro: humble
ros_domain_id: 0
registry: docker.io/dragomirxyz
image_prefix: lekiwiv2-arm64-
"""

HOSTS_RPI5 = """\
hosts:
  - name: rpi5
    ip: pi5.local
    user: user
    arch: arm64
"""

COMMON_PACKAGES = """\
common_packages:
  - name: my_msgs
    folder: common_packages/my_msgs
    repo: https://github.com/you/my_msgs.git
    branch: main
"""

MICRO_ROS_AGENT = """\
components:
  - name: micro_ros_agent
    folder: components/micro_ros_agent
    runs_on: rpi5
    apt_packages: []
    repositories:
      - url: https://github.com/micro-ROS/micro_ros_setup
        version: humble
        folder: micro_ros_agent
    postinstall:
      - "ros2 run micro_ros_setup create_agent_ws.sh"
      - "ros2 run micro_ros_setup build_agent.sh"
    entrypoint: ros2 run micro_ros_agent micro_ros_agent serial
    launch_args: "--dev /dev/ttyUSB0 -v6"
    devices:
      - "/dev/ttyUSB0:/dev/ttyUSB0"
"""

VNC_ON_ROBOT = """\
hosts:
  - name: rpi5
    ip: pi5.local
    user: user
    arch: arm64
components:
  - name: camera
    folder: components/camera
    runs_on: rpi5
    entrypoint: ros2 launch camera_bringup bringup.launch.py
    devices:
      - "/dev:/dev"
    resources:
      requests: {cpu: 0.5, memory: 256Mi}
      limits: {cpu: "1500m", memory: 1Gi}
      priority: critical
  - name: vnc
    image: ghcr.io/tiryoh/ros2-desktop-vnc:humble
    runs_on: rpi5
    ports:
      - "6080:80"
"""

HOSTS_WITH_DEVMACHINE = """\
hosts:
  - name: rpi5
    ip: pi5.local
    user: user
    arch: arm64
  - name: devmachine
    ip: 127.0.0.1
    user: your_username
    arch: amd64
"""

VNC_ON_DEVMACHINE = """\
components:
  - name: camera
    folder: components/camera
    runs_on: rpi5
    entrypoint: ros2 launch camera_bringup bringup.launch.py
    devices:
      - "/dev:/dev"
  - name: vnc
    image: ghcr.io/tiryoh/ros2-desktop-vnc:humble
    runs_on: devmachine
    nvidia: true
    ports:
      - "6080:80"
"""

MOVEIT_ON_DEVMACHINE = """\
components:
  - name: moveit_planner
    runs_on: devmachine
"""

MOVEIT_ON_ROBOT = """\
components:
  - name: moveit_planner
    runs_on: raspberrypi5
"""

#: Not among the fragments: the host that the "runs_on: raspberrypi5" fragment refers to.
HOST_RASPBERRYPI5 = """\
hosts:
  - name: raspberrypi5
    ip: 192.168.1.50
    user: robot
    arch: arm64
"""

JETSONS = """\
hosts:
  - name: main_computer
    ip: 192.168.1.100
    user: robot
    arch: amd64
  - name: jetson_front
    ip: 192.168.1.101
    user: robot
    arch: arm64
  - name: jetson_side
    ip: 192.168.1.102
    user: robot
    arch: arm64
  - name: jetson_rear
    ip: 192.168.1.103
    user: robot
    arch: arm64
components:
  - name: front_inference
    runs_on: jetson_front
    folder: components/perception_front
  - name: side_inference
    runs_on: jetson_side
    folder: components/perception_side
  - name: rear_inference
    runs_on: jetson_rear
    folder: components/perception_rear
  - name: perception_aggregator
    runs_on: main_computer
    folder: components/perception_aggregator
"""


@dataclass(frozen=True)
class Example:
    """A whole robot.yaml made of the example fragments, and the folders it needs."""

    name: str
    text: str
    folders: tuple[str, ...]


SEED_EXAMPLES = (
    Example("full", TOP + HOSTS_RPI5 + COMMON_PACKAGES + MICRO_ROS_AGENT, ("components/micro_ros_agent",)),
    Example("vnc_on_robot", TOP + VNC_ON_ROBOT, ("components/camera",)),
    Example("vnc_on_devmachine", TOP + HOSTS_WITH_DEVMACHINE + VNC_ON_DEVMACHINE, ("components/camera",)),
    Example("moveit_on_devmachine", TOP + HOSTS_WITH_DEVMACHINE + MOVEIT_ON_DEVMACHINE, ()),
    Example("moveit_on_robot", TOP + HOST_RASPBERRYPI5 + MOVEIT_ON_ROBOT, ()),
    Example(
        "jetsons",
        TOP + JETSONS,
        tuple(f"components/perception_{part}" for part in ("front", "side", "rear", "aggregator")),
    ),
)
