"""Names and labels of everything robocore creates: images, containers, paths in containers.

One place, so that stage, run, shell and status agree without passing names around.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # annotations only: status reads the labels without loading the configuration model
    from robocore.config.model import Robot

LABEL_PROJECT = "dev.robocore.project"
LABEL_COMPONENT = "dev.robocore.component"
LABEL_ROLE = "dev.robocore.role"  # component | discovery | shell | build
LABEL_INPUTS = "dev.robocore.inputs"  # content hash of what the image/container was made from
LABEL_SPEC = "dev.robocore.spec"  # hash of the container spec (run recreates only on change)
#: Values of :data:`LABEL_ROLE` on the containers ``run`` manages: a component, a discovery server.
ROLE_COMPONENT = "component"
ROLE_DISCOVERY = "discovery"
#: Roles of the containers ``run`` and ``down`` manage and ``status`` lists (dev shells and build containers are
#: left alone).
MANAGED_ROLES = (ROLE_COMPONENT, ROLE_DISCOVERY)

#: Where things live inside robocore's containers.
CONTAINER_WS = "/robocore/ws"  # the component's workspace (source), build and shell
CONTAINER_INSTALL = "/robocore/install"  # the component's colcon install tree
CONTAINER_DDS = "/robocore/dds"  # generated DDS profiles
ENTRYPOINT = "/robocore/entrypoint.sh"  # sources ROS and the install tree, then execs
#: The interpreter the entrypoint gives colcon's setup scripts for their helper (isolated, without site).
SETUP_PYTHON = "/robocore/setup-python"
#: Set in a container's environment, Docker's init (tini, ``init: true``) sends the signals it passes on (``docker
#: stop``'s SIGTERM) to its child's whole process group rather than to the child alone; a pod has no such init.
INIT_SIGNALS_GROUP = "TINI_KILL_PROCESS_GROUP"


#: A Docker image tag: a letter, digit or '_', then up to 127 letters, digits, '_', '.' or '-'.
TAG_PATTERN = r"^[A-Za-z0-9_][A-Za-z0-9_.\-]{0,127}$"
_TAG_RE = re.compile(TAG_PATTERN)


def is_image_tag(text: str) -> bool:
    """True when ``text`` is a valid Docker image tag (``v1.2``, ``2026-01-05``)."""
    return bool(_TAG_RE.fullmatch(text))


def image_prefix(robot: Robot, project_name: str) -> str:
    """``image_prefix`` from robot.yaml, else ``<project>-``."""
    return robot.image_prefix or f"{project_name}-"


def base_image(robot: Robot, project_name: str) -> str:
    """Repository name of the project's base image (no tag)."""
    return f"{image_prefix(robot, project_name)}base"


def component_image(robot: Robot, project_name: str, component: str) -> str:
    """Repository name of a component's staged image (no tag)."""
    return f"{image_prefix(robot, project_name)}{component}"


def registry_image(robot: Robot, image: str) -> str:
    """``image`` under the robot's registry, or unchanged without one."""
    return f"{robot.registry.rstrip('/')}/{image}" if robot.registry else image


def container_name(project_name: str, component: str) -> str:
    """The container of a deployed component."""
    return f"{project_name}-{component}"


def discovery_container_name(project_name: str, index: int) -> str:
    """The container of discovery server ``index``."""
    return f"{project_name}-discovery-{index}"


def shell_container_name(project_name: str, component: str, number: int = 0) -> str:
    """The dev-shell container of a component (``number`` > 0 for ``--new`` ones)."""
    suffix = f"-{number}" if number else ""
    return f"{project_name}-{component}-shell{suffix}"
