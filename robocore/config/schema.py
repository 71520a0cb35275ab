"""The JSON Schemas of robot.yaml and fleet.yaml, for editors (yaml-language-server) and for checks.

A schema describes the shape of the file (keys, types, allowed values); the
cross-field rules (``runs_on`` names a host, folders exist, every robot of the fleet gives
each host of robot.yaml, ...) are only checked by ``robocore validate``.
"""

from __future__ import annotations

import json
from typing import Any

from pydantic import BaseModel

from robocore.config.fleet import Fleet
from robocore.config.model import Robot

#: Stable identifier of the schema; editors match it, and it does not change between releases.
SCHEMA_ID = "https://robocore.dev/schema/robot.schema.json"
#: Stable identifier of the fleet file's schema.
FLEET_SCHEMA_ID = "https://robocore.dev/schema/fleet.schema.json"
DRAFT = "https://json-schema.org/draft/2020-12/schema"


def robot_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of robot.yaml."""
    return _document(Robot, SCHEMA_ID, "robocore robot.yaml",
                     "One robot: ROS 2 distro, hosts, common packages and components. "
                     "Cross-field rules are checked by 'robocore validate'.")


def fleet_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of fleet.yaml."""
    return _document(Fleet, FLEET_SCHEMA_ID, "robocore fleet.yaml",
                     "Many robots of one robot.yaml: each robot's host addresses, the engine and its manager, the "
                     "rollout policy (waves, health gate, timeouts). Checks against robot.yaml are made by "
                     "'robocore validate'.")


def _document(model: type[BaseModel], schema_id: str, title: str, description: str) -> dict[str, Any]:
    """``model``'s JSON Schema as a document of its own: the draft, its id, a title and a description."""
    schema = model.model_json_schema()
    schema["$schema"] = DRAFT
    schema["$id"] = schema_id
    schema["title"] = title
    schema["description"] = description
    return schema


def schema_json(*, fleet: bool = False) -> str:
    """The schema of robot.yaml (of fleet.yaml with ``fleet``) as indented JSON text."""
    return json.dumps(fleet_schema() if fleet else robot_schema(), indent=2, sort_keys=True)
