"""robocore: from one robot.yaml to ROS 2 containers on every machine of a robot."""

__version__ = "0.1.0"
