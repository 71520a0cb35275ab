"""The JSON Schema of robot.yaml, for editors (yaml-language-server) and for checks.

The schema describes the shape of the file (keys, types, allowed values); the
cross-field rules (``runs_on`` names a host, folders exist, ...) are only checked by
``robocore validate``.
"""

from __future__ import annotations

import json
from typing import Any

from robocore.config.model import Robot

#: Stable identifier of the schema; editors match it, and it does not change between releases.
SCHEMA_ID = "https://robocore.dev/schema/robot.schema.json"
DRAFT = "https://json-schema.org/draft/2020-12/schema"


def robot_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of robot.yaml."""
    schema = Robot.model_json_schema()
    schema["$schema"] = DRAFT
    schema["$id"] = SCHEMA_ID
    schema["title"] = "robocore robot.yaml"
    schema["description"] = (
        "One robot: ROS 2 distro, hosts, common packages and components. "
        "Cross-field rules are checked by 'robocore validate'."
    )
    return schema


def schema_json() -> str:
    """The schema as indented JSON text."""
    return json.dumps(robot_schema(), indent=2, sort_keys=True)
