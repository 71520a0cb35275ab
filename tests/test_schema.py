"""`robocore schema` prints a JSON Schema that accepts the robot.yaml examples and rejects malformed files."""

from __future__ import annotations

import copy
import functools
import json
import re
import subprocess
import sys
from typing import Any

import jsonschema
import pytest
import yaml
from config_examples import SEED_EXAMPLES, Example
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from pydantic import ValidationError
from test_config_invalid import BASE, edit
from test_config_property import VALID_DOCS, _get, _paths, mutated_documents

from robocore.config.model import Robot
from robocore.config.schema import SCHEMA_ID, robot_schema
from robocore.config.values import SHELL_WORDS, schema_pattern, shell_words


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


@pytest.mark.parametrize(("written", "accepted"), [("7.0", 7), ("0.0", 0), ("7.5", None), ("true", None),
                                                  ('"7"', None)])
def test_a_whole_number_with_a_point_is_accepted_by_both_and_nothing_else(schema: dict[str, Any], written: str,
                                                                          accepted: int | None) -> None:
    """JSON Schema's integer takes 7.0, so robocore does too (as 7); 7.5, a boolean and a string neither does."""
    data = yaml.safe_load(edit({2: f"ros_domain_id: {written}"}))
    assert _validator(schema).is_valid(data) is (accepted is not None)
    if accepted is None:
        with pytest.raises(ValidationError):
            Robot.model_validate(data)
    else:
        assert Robot.model_validate(data).ros_domain_id == accepted


def test_cross_field_rules_are_left_to_validate(schema: dict[str, Any]) -> None:
    """The schema checks shape only: an unknown runs_on host passes it (robocore validate reports it)."""
    assert _validator(schema).is_valid(yaml.safe_load(edit({15: "    runs_on: rpi6"})))


FIELD_RULES = {
    "ip-with-space": edit({6: "    ip: 192.168.1.20 extra"}),
    "ip-with-slash": edit({6: "    ip: 192.168.1.0/24"}),
    "relative-mount-root": edit(after={8: "    mount_root: robocore"}),
    "repository-folder-escapes": edit(after={15: "    repositories:\n      - {url: https://x/y, folder: a/../../z}"}),
}


@pytest.mark.parametrize("name", sorted(FIELD_RULES))
def test_field_rules_are_in_the_schema_too(schema: dict[str, Any], name: str) -> None:
    data = yaml.safe_load(FIELD_RULES[name])
    with pytest.raises(ValidationError):
        Robot.model_validate(data)
    assert not _validator(schema).is_valid(data)


TRICKY = st.one_of(
    st.sampled_from(["a b", "a/b", "/abs", "rel", "..", "a/../b", "", " ", "-x", "X", "1a", "a" * 70, "Root", "ok_name",
                     "curl=1.0", "pip pkg", "x;y", "6080:80", "/dev/x:/dev/x:rwm", "12345"]),
    st.text(max_size=12),
)


@st.composite
def restrung_documents(draw: st.DrawFn) -> Any:
    """A robot.yaml example whose string values are replaced by tricky strings: the shape stays, the content varies."""
    doc = copy.deepcopy(draw(st.sampled_from(VALID_DOCS)))
    leaves = [path for path in _paths(doc) if path and isinstance(_get(doc, path), str)]
    for path in draw(st.lists(st.sampled_from(leaves), min_size=1, max_size=3)):
        _get(doc, path[:-1])[path[-1]] = draw(TRICKY)
    return doc


@settings(max_examples=500, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.one_of(mutated_documents(), restrung_documents()))
def test_what_the_schema_accepts_the_model_accepts(doc: Any) -> None:
    """Editors never call a file fine that robocore's field checks reject (shape only: no cross-field rules)."""
    accepted = _shared_validator().is_valid(doc)
    event("schema accepts" if accepted else "schema rejects")
    if accepted:
        Robot.model_validate(doc)


@functools.cache
def _shared_validator() -> jsonschema.Draft202012Validator:
    return _validator(robot_schema())


@settings(max_examples=500)
@given(st.text(alphabet=st.sampled_from(list("ab '\"\\#$é\x01")), max_size=12))
def test_the_schemas_shell_words_pattern_agrees_with_the_models_check(text: str) -> None:
    """An entrypoint the schema accepts splits as a shell would, and one that does not is refused by both."""
    try:
        shell_words(text)
        model_accepts = True
    except ValueError:
        model_accepts = False
    assert (re.search(schema_pattern(SHELL_WORDS), text) is not None) == model_accepts


@pytest.mark.parametrize(("entrypoint", "valid"), [("\\", False), ("say 'a", False), ('say "a\\"', False),
                                                   ("say 'a b' \\ c", True), ('say "a \\" b"', True)])
def test_the_schema_refuses_an_entrypoint_no_shell_can_split(entrypoint: str, valid: bool) -> None:
    doc = copy.deepcopy(VALID_DOCS[0])
    doc["components"][0]["entrypoint"] = entrypoint
    assert _shared_validator().is_valid(doc) is valid
