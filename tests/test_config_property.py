"""Property: whatever robot.yaml holds, loading ends in a Robot or a ConfigError, never another exception.

Documents are valid robot.yaml examples mutated at random (keys dropped, renamed or added, values
replaced by values of other types), random YAML values, YAML token soup, random text and
random bytes, and deeply nested structures.
"""

from __future__ import annotations

import copy
import string
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml
from config_examples import SEED_EXAMPLES
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from robocore.config.loader import load_robot, parse_robot_text
from robocore.config.model import Robot
from robocore.errors import ConfigError

FILE = "robot.yaml"
EXAMPLES = 500
PROPERTY = settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.too_slow])

# One project folder for the whole module: the examples' folders exist in it, so mutated
# documents also exercise the file-system checks. (A function-scoped tmp_path would be shared by
# every hypothesis example anyway.)
_ROOT = Path(tempfile.mkdtemp(prefix="robocore-property-"))
for _example in SEED_EXAMPLES:
    for _folder in _example.folders:
        (_ROOT / _folder).mkdir(parents=True, exist_ok=True)
VALID_DOCS = [yaml.safe_load(example.text) for example in SEED_EXAMPLES]

KEYS = [
    "ros_distro", "ros_domain_id", "registry", "image_prefix", "base", "discovery", "hosts", "common_packages",
    "components", "name", "ip", "user", "arch", "docker", "docker_port", "tls", "insecure", "mount_root", "folder",
    "repo", "branch", "runs_on", "image", "apt_packages", "pip_packages", "repositories", "postinstall", "entrypoint",
    "launch_args", "devices", "ports", "environment", "volumes", "network", "nvidia", "gui", "privileged", "servers",
    "desktop", "display", "web_port", "vnc_port", "local_only", "open", "size",
    "port", "host", "transport", "kind", "url", "version", "resources", "requests", "limits", "cpu", "memory",
    "priority", "bogus", "",
]

scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(),
    st.integers(min_value=-(2**80), max_value=2**80),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=30),
    st.sampled_from(["humble", "iron", "rpi5", "pi5.local", "127.0.0.1", "localhost", "::1", "6080:80", "/dev:/dev",
                     "../..", "/", ".", "tcp", "tls", "ssh", "local", "wheels", "host", "bridge", "arm64", "~", "-1",
                     "components/camera", "a" * 300, "line\nbreak", "tab\there", "\u00e9\u4e2d", "0x1F", "1e400",
                     "500m", "256Mi", "1.5", "critical"]),
)
yaml_values = st.recursive(
    scalars,
    lambda children: st.one_of(
        st.lists(children, max_size=4),
        st.dictionaries(st.one_of(st.sampled_from(KEYS), st.text(max_size=8), st.integers()), children, max_size=4),
    ),
    max_leaves=12,
)


def outcome(call: Callable[[], Robot]) -> Robot | ConfigError:
    """Run ``call``; a Robot or a ConfigError are the only acceptable outcomes (anything else fails the test)."""
    try:
        return call()
    except ConfigError as error:
        lines = error.lines()
        assert lines, "a ConfigError without problems"
        assert str(error).splitlines() == lines
        for line in lines:
            assert line.startswith(FILE), line
            assert "\n" not in line and "\r" not in line
        return error


def parse(text: str) -> Robot | ConfigError:
    return outcome(lambda: parse_robot_text(text, file=FILE, project=_ROOT))


def _paths(node: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    out = [path]
    if isinstance(node, dict):
        for key, value in node.items():
            out += _paths(value, (*path, key))
    elif isinstance(node, list):
        for index, value in enumerate(node):
            out += _paths(value, (*path, index))
    return out


def _get(node: Any, path: tuple[Any, ...]) -> Any:
    for part in path:
        node = node[part]
    return node


@st.composite
def mutated_documents(draw: st.DrawFn) -> Any:
    """A robot.yaml example with 1-4 random mutations."""
    doc = copy.deepcopy(draw(st.sampled_from(VALID_DOCS)))
    for _ in range(draw(st.integers(min_value=1, max_value=4))):
        paths = _paths(doc)
        path = draw(st.sampled_from(paths))
        action = draw(st.sampled_from(["replace", "delete", "add_key", "rename", "duplicate_item", "wrap"]))
        if not path:
            if action == "replace":
                doc = draw(yaml_values)
            continue
        parent, last = _get(doc, path[:-1]), path[-1]
        if not isinstance(parent, (dict, list)):
            continue
        if action == "replace":
            parent[last] = draw(yaml_values)
        elif action == "delete":
            del parent[last]
        elif action == "add_key" and isinstance(parent, dict):
            parent[draw(st.sampled_from(KEYS))] = draw(yaml_values)
        elif action == "rename" and isinstance(parent, dict):
            parent[draw(st.sampled_from(KEYS))] = parent.pop(last)
        elif action == "duplicate_item" and isinstance(parent, list):
            parent.append(copy.deepcopy(parent[last]))
        elif action == "wrap":
            parent[last] = draw(st.sampled_from([[parent[last]], {"x": parent[last]}, str(parent[last])]))
        if not isinstance(doc, (dict, list)):
            break
    return doc


@PROPERTY
@given(mutated_documents(), st.sampled_from(["block", "flow"]))
def test_mutated_seed_documents(doc: Any, style: str) -> None:
    text = yaml.safe_dump(doc, default_flow_style=(style == "flow"), allow_unicode=True)
    result = parse(text)
    if isinstance(result, Robot):
        # a mutation may keep the document valid; then it must round-trip to the same data
        assert parse_robot_text(text, project=_ROOT) == result


@PROPERTY
@given(yaml_values)
def test_random_yaml_values(value: Any) -> None:
    parse(yaml.safe_dump(value, allow_unicode=True))


TOKENS = [
    "ros_distro:", "hosts:", "components:", "name:", "runs_on:", "- ", "  ", "    ", "\n", "\t", ": ", "&a ", "*a",
    "&b ", "*b", "<<: *a", "!!binary ", "!!python/object:os.system ", "!!set ", "!!omap ", "!!timestamp ", "!custom ",
    "{", "}", "[", "]", ",", "'", '"', "#", "|", ">", "? ", "%YAML 1.1\n", "---\n", "...\n", "humble", "rpi5",
    "2001-12-14", "0o17", "0x1F", ".inf", ".nan", "~", "null", "yes", "on", "\\", "\u2028", "\ufeff", "\r\n", "@", "`",
]


@PROPERTY
@given(st.lists(st.sampled_from(TOKENS), max_size=40))
def test_yaml_token_soup(tokens: list[str]) -> None:
    parse("".join(tokens))


@PROPERTY
@given(st.text(max_size=300))
def test_random_text(text: str) -> None:
    parse(text)


@PROPERTY
@given(st.binary(max_size=300), st.sampled_from(["utf-8", "latin-1", "utf-16"]))
def test_random_bytes_decoded(data: bytes, encoding: str) -> None:
    parse(data.decode(encoding, errors="replace"))


@settings(max_examples=100, deadline=None)
@given(st.integers(min_value=1, max_value=2000), st.sampled_from(["[", "{a: ", "- ", "mapping", "alias"]))
def test_deep_nesting(depth: int, kind: str) -> None:
    if kind == "mapping":
        depth = min(depth, 300)  # block mappings grow quadratically with depth
        text = "".join("  " * i + f"k{i}:\n" for i in range(depth)) + "  " * depth + "x\n"
    elif kind == "alias":
        lines = ["a0: &a0 [x, x, x, x, x, x, x, x]"]
        lines += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 8)}]" for i in range(1, min(depth, 12))]
        text = "\n".join(lines) + "\n"
    else:
        text = kind * depth + "x"
    parse(text)


@PROPERTY
@given(st.one_of(st.binary(max_size=200), mutated_documents().map(lambda d: yaml.safe_dump(d).encode("utf-8"))))
def test_load_robot_from_disk(data: bytes) -> None:
    (_ROOT / FILE).write_bytes(data)
    try:
        load_robot(_ROOT)
    except ConfigError as error:
        for line in error.lines():
            assert line.startswith(str(_ROOT / FILE)) or line.startswith(FILE), line
            assert "\n" not in line and "\r" not in line


def test_the_mutation_strategy_reaches_both_outcomes() -> None:
    """A negative control: the example documents are valid, and garbage is rejected, through the same helper."""
    assert all(isinstance(parse(yaml.safe_dump(doc)), Robot) for doc in VALID_DOCS)
    assert isinstance(parse("hosts: 1\n"), ConfigError)
    assert all(c in string.printable for c in FILE)
