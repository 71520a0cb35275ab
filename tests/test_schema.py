"""`robocore schema` prints a JSON Schema that accepts the seed examples and rejects malformed files."""

from __future__ import annotations

import json
import subprocess
import sys
from typing import Any

import jsonschema
import pytest
import yaml
from config_examples import SEED_EXAMPLES, Example
from test_config_invalid import BASE, edit

from robocore.config.schema import SCHEMA_ID, robot_schema


@pytest.fixture(scope="module")
def schema() -> dict[str, Any]:
    """The schema as the command prints it."""
    done = subprocess.run([sys.executable, "-m", "robocore", "schema"], capture_output=True, text=True, check=True)
    printed: dict[str, Any] = json.loads(done.stdout)
    return printed


def _validator(schema: dict[str, Any]) -> jsonschema.Draft202012Validator:
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def test_printed_schema_is_a_valid_draft_2020_12_schema_with_a_stable_id(schema: dict[str, Any]) -> None:
    jsonschema.Draft202012Validator.check_schema(schema)
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert schema["$id"] == SCHEMA_ID == "https://robocore.dev/schema/robot.schema.json"
    assert schema == robot_schema()
    assert schema["additionalProperties"] is False
    assert set(schema["required"]) == {"ros_distro", "hosts"}


@pytest.mark.parametrize("example", SEED_EXAMPLES, ids=[e.name for e in SEED_EXAMPLES])
def test_seed_examples_satisfy_the_schema(schema: dict[str, Any], example: Example) -> None:
    errors = list(_validator(schema).iter_errors(yaml.safe_load(example.text)))
    assert errors == []


REJECTED = {
    "unknown-distro": edit({1: "ros_distro: iron"}),
    "domain-id-too-big": edit({2: "ros_domain_id: 233"}),
    "unknown-top-level-key": edit(after={3: "bogus: 1"}),
    "unknown-host-key": edit(after={8: "    hostname: pi"}),
    "bad-arch": edit({8: "    arch: armhf"}),
    "missing-ros-distro": edit(delete=(1,)),
    "host-ip-missing": edit(delete=(6,)),
    "bad-bool": edit(after={15: "    nvidia: maybe"}),
    "apt-not-a-list": edit(after={15: "    apt_packages: curl"}),
    "bad-component-name": edit({13: "  - name: 1talker"}),
    "bad-docker-access": edit(after={8: "    docker: telnet"}),
    "discovery-port-low": edit(after={3: "discovery:\n  servers:\n    - {host: rpi5, port: 80}"}),
    "base-kind": edit(after={3: "base:\n  kind: docker"}),
    "env-value-list": edit(after={15: "    environment:\n      A: [1]"}),
}


@pytest.mark.parametrize("name", sorted(REJECTED))
def test_schema_rejects_malformed_documents(schema: dict[str, Any], name: str) -> None:
    assert not _validator(schema).is_valid(yaml.safe_load(REJECTED[name]))


def test_schema_accepts_the_base_document_and_values_robocore_coerces(schema: dict[str, Any]) -> None:
    validator = _validator(schema)
    assert validator.is_valid(yaml.safe_load(BASE))
    # environment values may be written as numbers and booleans; robocore turns them into text
    assert validator.is_valid(
        yaml.safe_load(edit(after={15: "    environment:\n      A: 1\n      B: true\n      C: x"}))
    )


def test_cross_field_rules_are_left_to_validate(schema: dict[str, Any]) -> None:
    """The schema checks shape only: an unknown runs_on host passes it (robocore validate reports it)."""
    assert _validator(schema).is_valid(yaml.safe_load(edit({15: "    runs_on: rpi6"})))
