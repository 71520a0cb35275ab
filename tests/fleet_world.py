"""A fleet project in memory for the fleet commands' unit tests: one robot.yaml model with a talker on one host,
a fleet file's text, and a clock that the code under test's ``sleep``s move (no daemon, no manager, no waiting)."""

from __future__ import annotations

from pathlib import Path

from robocore.commands.fleet_swarm import FleetProject
from robocore.config.fleet import parse_fleet_text
from robocore.config.loader import parse_robot_text
from robocore.plan.fleet import fleet_instances
from robocore.project import Project

#: robot.yaml of the tests' robots: a Jazzy talker on one host, ``main``.
#: A fleet file's manager, registry and two robots of one host each (r1, r2): what the fleet tests add to it follows.
TWO_ROBOTS = """\
manager: {ip: 10.0.0.2}
registry: 10.0.0.2:5000
robots:
  - {name: r1, hosts: {main: {ip: 10.1.1.1}}}
  - {name: r2, hosts: {main: {ip: 10.1.2.1}}}
"""
ONE_TALKER = """\
ros_distro: jazzy
hosts:
  - {name: main, ip: 127.0.0.1, user: me}
components:
  - {name: talker, folder: components/talker, runs_on: main, entrypoint: ros2 run demo_talker talker}
"""


def fleet_project(root: Path, fleet_text: str, robot_text: str = ONE_TALKER) -> FleetProject:
    """The project at ``root`` (nothing written there) with robot.yaml ``robot_text`` and fleet.yaml ``fleet_text``."""
    robot = parse_robot_text(robot_text)
    fleet = parse_fleet_text(fleet_text, robot)
    return FleetProject(project=Project(root=root, robot=robot), fleet=fleet,
                        instances=fleet_instances(robot, fleet))


class Clock:
    """``time`` for the gate and the lock's asker: ``monotonic()`` is what their ``sleep``s added up to."""

    def __init__(self) -> None:
        self.now = 1000.0

    def monotonic(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += seconds
