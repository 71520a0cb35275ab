"""The Kubernetes export's YAML text (names.dump) is PyYAML's text, byte for byte, whatever the values hold.

names.dump writes through robocore.plan.yaml_text's direct writer (with the export's width and unicode); these
tests compare it with what the export wrote before, ``yaml.dump`` with libyaml's emitter, on hostile values, shared
objects (anchors) and empty collections.
"""

from __future__ import annotations

from typing import Any

import pytest
import yaml
from hypothesis import given
from test_yaml_text import HOSTILE, PROPERTY, _values

from robocore.plan.kubernetes import names


def pyyaml(documents: list[Any]) -> str:
    """The export's text as PyYAML writes it (what names.dump wrote before the direct writer)."""
    return names.HEADER + "---\n".join(
        yaml.dump(doc, Dumper=yaml.CSafeDumper, sort_keys=False, default_flow_style=False, width=1 << 16,
                  allow_unicode=True) for doc in documents)


def pod(value: Any) -> dict[str, Any]:
    """A DaemonSet-like document with ``value`` wherever an export puts a string."""
    return {
        "apiVersion": "apps/v1", "kind": "DaemonSet",
        "metadata": {"name": "talker", "labels": {"robocore.dev/component": value, "x": value}},
        "spec": {"template": {"spec": {
            "nodeSelector": {"kubernetes.io/arch": "amd64"},
            "containers": [{"name": "main", "image": value, "command": ["bash", "-c", value],
                            "env": [{"name": "A", "value": value}, {"name": value, "value": "0"}],
                            "resources": {}, "ports": []}],
            "volumes": [{"name": "v", "emptyDir": {}}],
        }}},
    }


@pytest.mark.parametrize("value", [v for v in HOSTILE if not any("\ud800" <= c <= "\udfff" for c in v)])
def test_hostile_values_are_written_as_pyyaml_writes_them(value: str) -> None:
    documents = [pod(value), {"kind": "List", "items": [value, {"k": value}]}]
    text = names.dump(documents)
    assert text == pyyaml(documents)
    assert list(yaml.safe_load_all(text.split("\n", 1)[1])) == documents


def test_non_ascii_is_written_as_it_is() -> None:
    text = names.dump([{"env": [{"name": "GREETING", "value": "héllo: wörld # no comment"}, {"v": "中文"}]}])
    assert "héllo: wörld # no comment" in text and "中文" in text
    assert text == pyyaml([{"env": [{"name": "GREETING", "value": "héllo: wörld # no comment"}, {"v": "中文"}]}])


def test_a_long_value_with_spaces_is_not_folded() -> None:
    value = "word " * 2000 + "end"
    text = names.dump([{"a": {"b": [value]}}])
    assert f"  - {value}\n" in text
    assert text == pyyaml([{"a": {"b": [value]}}])


def test_a_shared_object_is_an_anchor_as_pyyaml_writes_it() -> None:
    """The health Job's containers share one list of mounts: PyYAML writes an anchor and an alias."""
    mounts = [{"name": "scripts", "mountPath": "/robocore/health", "readOnly": True}]
    document = {"spec": {"containers": [{"name": "a", "volumeMounts": mounts}, {"name": "b", "volumeMounts": mounts}]}}
    text = names.dump([document])
    assert "&id001" in text and "*id001" in text
    assert text == pyyaml([document])


def test_an_equal_but_distinct_object_is_written_twice() -> None:
    document = {"a": [{"x": 1}], "b": [{"x": 1}]}
    assert names.dump([document]) == pyyaml([document]) == names.HEADER + "a:\n- x: 1\nb:\n- x: 1\n"


@PROPERTY
@given(_values)
def test_any_document_is_written_as_pyyaml_writes_it(document: Any) -> None:
    if "\\ud" in repr(document).lower():  # a lone surrogate: no export holds one (robot.yaml refuses it)
        return
    assert names.dump([{"doc": document}, document]) == pyyaml([{"doc": document}, document])
