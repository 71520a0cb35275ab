"""The JSON Schema of robot.yaml, for editors (yaml-language-server) and for checks."""

from __future__ import annotations

import json
from typing import Any

from robocore.config.model import Robot

SCHEMA_ID = "https://robocore.dev/schema/robot.schema.json"


def robot_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of robot.yaml."""
    schema = Robot.model_json_schema()
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "robocore robot.yaml"
    return schema


def schema_json() -> str:
    """The schema as indented JSON text."""
    return json.dumps(robot_schema(), indent=2, sort_keys=True)
