"""yaml_text.dump writes PyYAML's very text, and reads back as the document, whatever the values hold.

Compose files are written by it: hostile values from robot.yaml (quotes, colons, line breaks, unicode, ``#``, a
leading ``-``, ``yes``/``no``/``on``/``off``, numbers as strings, empty strings, very long strings) must come out
quoted exactly as PyYAML quotes them, so that docker compose reads what ``run`` gives the containers.
"""

from __future__ import annotations

import re
import string
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from robocore.plan import yaml_text

PROPERTY = settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])

HOSTILE = [
    "", " ", "  lead", "trail ", "it's", 'say "hi"', "'", '"', "a: b", "a:", ":a", "a:b", "key: value: more",
    "line\nbreak", "two\n\nbreaks", "\n", "tab\there", "cr\rhere", "nel\x85here", "ls\u2028here", "nul\x00",
    "\x7f", "\u00e9t\u00e9", "\u4e2d\u6587", "emoji \U0001F600", "# comment", "a #b", "a#b", "#", "-", "- item",
    "-c", "--", "---", "--- doc", "...", "...x", "?", "? q", "!tag", "&anchor", "*alias", "|", ">", "%TAG", "@at",
    "`tick", "{a: 1}", "[1]", ",", "a, b", "yes", "no", "on", "off", "Yes", "NO", "On", "OFF", "y", "n", "Y", "N",
    "true", "False", "TRUE", "null", "Null", "~", "0", "00", "012", "0o17", "0x1F", "0b101", "1_000", "-1", "+1",
    "1.5", "-.5", "1e3", "1e400", ".inf", "-.INF", ".nan", "1:30", "190:20:30", "2001-12-14",
    "2001-12-14 21:59:43.10 -5", "<<", "=", "a=b", "$$HOME", "${VAR:-x}", "C:\\path", "back\\slash", "x" * 127,
    "x" * 128, "x" * 300, "word " * 40, "w " * 60 + "w",
    "marker=\"/robocore/x\"; if [ -e \"$$m\" ]; then echo 'a: b'; fi",
    "a\udc80b", "\ud800", "lone \udfff surrogate",  # a lone surrogate, which libyaml cannot encode
]


def pyyaml(document: Any, dumper: type[yaml.SafeDumper] = yaml_text.DUMPER) -> str:
    try:
        return yaml.dump(document, Dumper=dumper, sort_keys=False, default_flow_style=False, width=yaml_text.WIDTH)
    except UnicodeEncodeError:  # libyaml cannot encode a lone surrogate; PyYAML's own emitter escapes it
        return yaml.dump(document, Dumper=yaml.SafeDumper, sort_keys=False, default_flow_style=False,
                         width=yaml_text.WIDTH)


def shaped(value: Any) -> dict[str, Any]:
    """A compose-like document with ``value`` in every place a compose file puts a string."""
    return {
        "services": {
            "svc": {
                "image": value,
                "command": ["sh", "-c", value, "-x"],
                "environment": {"PLAIN": "/robocore/dds/client.xml", "VALUE": value, "ROS_DOMAIN_ID": "0"},
                "init": True,
                "deploy": {"resources": {"reservations": {"devices": [
                    {"driver": value, "count": "all", "capabilities": [value, "gpu"]}]}}},
                "labels": {"dev.robocore.spec": "ad301252a858d133", "x": value},
            },
        },
        "volumes": {"v": {"name": value}},
    }


@pytest.mark.parametrize("value", HOSTILE)
def test_hostile_value_is_written_as_pyyaml_writes_it(value: str) -> None:
    document = shaped(value)
    text = yaml_text.dump(document)
    assert text == pyyaml(document)
    assert yaml.safe_load(text) == document


@pytest.mark.parametrize("value", HOSTILE)
def test_hostile_key_is_written_as_pyyaml_writes_it(value: str) -> None:
    document = {"services": {"svc": {"environment": {value: "v", "B": value}, "labels": {value: value}}}}
    text = yaml_text.dump(document)
    assert text == pyyaml(document)
    assert yaml.safe_load(text) == document


@pytest.mark.parametrize("indent", range(0, 12))
@pytest.mark.parametrize("length", [100, 110, 114, 115, 116, 117, 118, 119, 120, 121, 130])
def test_long_strings_with_spaces_break_where_pyyaml_breaks_them(indent: int, length: int) -> None:
    """Near the line width PyYAML folds a string at a space; the same lines come out, at every depth."""
    value = ("ab cd " * 40)[:length].strip()
    document: dict[str, Any] = {"k" * (indent + 1): value, "l": [value, {"m": value}]}
    for _ in range(indent % 4):
        document = {"n": document}
    assert yaml_text.dump(document) == pyyaml(document)


def test_the_text_is_libyamls_and_pythons_on_plain_compose_values() -> None:
    """Both of PyYAML's emitters agree on what compose files hold (they differ on some edge cases, such as an
    empty key, where robocore's text is libyaml's when PyYAML has it, as before)."""
    document = shaped("ghcr.io/org/img:v1")
    assert yaml_text.dump(document) == pyyaml(document, yaml.SafeDumper)


def test_values_other_than_strings() -> None:
    document = {"a": [1, -5, 10**30, True, False, None, 1.5, [], {}, [1, [2]]], "b": {}, "c": [], "d": 0.1,
                "e": {2: "int key", None: "null key", False: "bool key"}}
    text = yaml_text.dump(document)
    assert text == pyyaml(document)
    assert yaml.safe_load(text) == document


def test_empty_and_non_mapping_documents() -> None:
    for document in ({}, [], "text", None):
        assert yaml_text.dump(document) == pyyaml(document)  # type: ignore[arg-type]


def test_shared_objects_read_back_equal() -> None:
    """PyYAML writes an object met twice as an anchor and an alias; the direct writer writes it twice: the same
    document when read."""
    shared = ["a", "b"]
    document = {"x": shared, "y": shared, "z": {"w": shared}}
    assert yaml.safe_load(yaml_text.dump(document)) == document


_ALPHABET = string.ascii_letters[:8] + string.digits[:3] + " -_.:/@'\"#,%~=+?!&*|>{}[]\n\t\\\u00e9\u2028\x85yYnN\udc80"
_scalars = st.one_of(
    st.text(alphabet=_ALPHABET, max_size=16),
    st.sampled_from(HOSTILE),
    st.text(max_size=8),
    st.integers(),
    st.booleans(),
    st.none(),
)
_values = st.recursive(
    _scalars,
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(_scalars.filter(
        lambda v: isinstance(v, str)), inner, max_size=4)),
    max_leaves=25,
)


@PROPERTY
@given(st.dictionaries(st.one_of(st.text(alphabet=_ALPHABET, max_size=12), st.sampled_from(HOSTILE)), _values,
                       max_size=6))
def test_any_document_is_written_as_pyyaml_writes_it(document: dict[str, Any]) -> None:
    text = yaml_text.dump(document)
    if not re.search(r"\\ud[89a-f]", repr(document)):  # a lone surrogate's entry is PyYAML's own emitter's text,
        assert text == pyyaml(document)  # which differs from libyaml's elsewhere: that document reads back, below
    assert yaml.safe_load(text) == document
