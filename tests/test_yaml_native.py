"""robot.yaml and fleet.yaml are composed by libyaml's compiled composer (yamltext.NativeLoader), the depth limit
checked on the composed document: every file reads as it read through PyYAML's composer, and every refusal is the
same line, word for word (the composer that reads it the old way is yamltext._FastLoader)."""

from __future__ import annotations

import gc
from typing import Any

import pytest

from robocore.config import yamltext
from robocore.errors import ConfigError


def nested(depth: int, leaf: str = "x", *, flow: bool = False) -> str:
    """A document whose deepest node is ``depth`` levels deep (the root is level 1)."""
    if flow:
        return "a: " + "[" * (depth - 2) + leaf + "]" * (depth - 2) + "\n"
    return "".join(f"{'  ' * i}k{i}:\n" for i in range(depth - 2)) + f"{'  ' * (depth - 2)}k: {leaf}\n"


DOCUMENTS = [
    "hosts:\n  - {name: main, ip: 10.0.0.1}\n",
    nested(50), nested(51), nested(52), nested(50, flow=True), nested(51, flow=True), nested(300, flow=True),
    nested(2000, flow=True),
    # an alias counts where it stands: one level, whatever the depth of what it names
    "a: &a " + "[" * 45 + "1" + "]" * 45 + "\nb: " + "[" * 40 + "*a" + "]" * 40 + "\n",
    "a: &a [1]\nb: " + "[" * 48 + "*a" + "]" * 48 + "\n",
    "a: &a [1]\nb: " + "[" * 49 + "*a" + "]" * 49 + "\n",
    "a: &a [1]\n" + nested(51, "*a"),
    "a: &a [*a]\n", "a: *nowhere\n", "a: &x 1\nb: &x 2\nc: *x\n", "a: 1\na: 2\n", "<<: {a: 1}\nb: 2\n",
    "a: [1, 2\n", "a: 012\n", "a: '\\u00e9'\nb: \"\\udc80\"\n", "a: !!binary 'x'\n", "- a\n- b: [c, {d: e}]\n", "",
    "# only a comment\n", "a: 1\n---\nb: 2\n",
]


def read(text: str) -> Any:
    """What read_yaml gives: the values, every key's line and the duplicates; or the refusal's lines."""
    try:
        data, lines = yamltext.read_yaml(text, "robot.yaml")
    except ConfigError as error:
        return [str(problem) for problem in error.problems]
    return data, lines.lines, lines.duplicates


@pytest.mark.parametrize("text", DOCUMENTS)
def test_every_document_reads_as_through_pythons_composer(text: str, monkeypatch: pytest.MonkeyPatch) -> None:
    new = read(text)
    monkeypatch.setattr(yamltext, "NativeLoader", None)
    assert new == read(text)


@pytest.mark.parametrize(("depth", "refused"), [(50, False), (51, True), (999, True)])
def test_the_depth_limit_holds(depth: int, refused: bool) -> None:
    result = read(nested(depth, flow=True))
    assert (result == [f"robot.yaml:1: YAML is nested more than {yamltext.MAX_DEPTH} levels deep"]) is refused


def test_the_native_composer_is_the_one_used(monkeypatch: pytest.MonkeyPatch) -> None:
    """A negative control: without libyaml's composer the check above would compare the old path with itself."""
    made: list[str] = []
    native: Any = yamltext.NativeLoader
    assert native is not None

    class Spy(native):  # type: ignore[misc,valid-type]
        def __init__(self, stream: str, file: str) -> None:
            made.append(file)
            super().__init__(stream, file)

    monkeypatch.setattr(yamltext, "NativeLoader", Spy)
    assert yamltext.read_yaml("a: [1]\n", "fleet.yaml")[0] == {"a": [1]}
    assert made == ["fleet.yaml"]


def test_the_collector_runs_again_after_a_reading_and_a_refusal() -> None:
    yamltext.read_yaml("a: 1\n", "robot.yaml")
    assert gc.isenabled()
    with pytest.raises(ConfigError):
        yamltext.read_yaml("a: [1\n", "robot.yaml")
    assert gc.isenabled()
