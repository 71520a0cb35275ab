"""Load robot.yaml into a :class:`~robocore.config.model.Robot`, or fail with every problem.

The YAML is composed into nodes first so that each key path can be traced back to its
line; pydantic's errors and the cross-field checks are then reported together, one
line each, as ``robot.yaml:14: components[0].runs_on: unknown host 'rpi6' (known: rpi5)``.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from robocore.config.checks import check_robot
from robocore.config.model import Robot
from robocore.errors import ConfigError, Problem

KeyPath = tuple[str | int, ...]

ROBOT_FILE = "robot.yaml"


def format_path(path: Iterable[str | int]) -> str:
    """Render a key path the way users write it: ``components[0].runs_on``."""
    out = ""
    for part in path:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += f".{part}" if out else str(part)
    return out


class LineMap:
    """Line numbers (1-based) of every key path in a YAML document."""

    def __init__(self) -> None:
        self.lines: dict[KeyPath, int] = {}
        self.duplicates: list[tuple[KeyPath, int]] = []

    def add(self, node: yaml.Node, path: KeyPath = ()) -> None:
        """Record ``node`` and its children under ``path``."""
        self.lines.setdefault(path, node.start_mark.line + 1)
        if isinstance(node, yaml.MappingNode):
            seen: set[str] = set()
            for key_node, value_node in node.value:
                key = key_node.value if isinstance(key_node, yaml.ScalarNode) else str(key_node.value)
                child = (*path, key)
                if key in seen:
                    self.duplicates.append((child, key_node.start_mark.line + 1))
                seen.add(key)
                self.lines[child] = key_node.start_mark.line + 1
                self.add_value(value_node, child)
        elif isinstance(node, yaml.SequenceNode):
            for index, item in enumerate(node.value):
                self.add(item, (*path, index))

    def add_value(self, node: yaml.Node, path: KeyPath) -> None:
        """Record the children of a mapping value without moving the key's own line."""
        if isinstance(node, (yaml.MappingNode, yaml.SequenceNode)):
            keep = self.lines[path]
            self.add(node, path)
            self.lines[path] = keep

    def line_of(self, path: Sequence[str | int]) -> int | None:
        """The line of ``path``, or of its nearest ancestor that is in the file."""
        probe = tuple(path)
        while probe:
            if probe in self.lines:
                return self.lines[probe]
            probe = probe[:-1]
        return self.lines.get(())


def _friendly(error: dict[str, Any]) -> str:
    kind = error.get("type", "")
    ctx = error.get("ctx") or {}
    if kind == "missing":
        return "required key is missing"
    if kind == "extra_forbidden":
        return "unknown key"
    if kind == "enum":
        return f"{error.get('input')!r} is not one of {ctx.get('expected', '')}"
    if kind == "literal_error":
        return f"{error.get('input')!r} is not one of {ctx.get('expected', '')}"
    if kind == "string_pattern_mismatch":
        return f"{error.get('input')!r} is not a valid value here"
    msg = str(error.get("msg", "invalid value"))
    if msg.startswith("Value error, "):
        msg = msg[len("Value error, "):]
    return msg[:1].lower() + msg[1:]


def _allowed_keys(model: type[Any], loc: Sequence[str | int]) -> list[str]:
    """The keys allowed at the mapping that contains ``loc`` (for 'unknown key' hints)."""
    from pydantic import BaseModel

    current: Any = model
    for part in loc[:-1]:
        if isinstance(part, int):
            continue
        fields = getattr(current, "model_fields", None)
        if not fields or part not in fields:
            return []
        annotation = fields[part].annotation
        current = _model_in(annotation)
        if current is None:
            return []
    if isinstance(current, type) and issubclass(current, BaseModel):
        return sorted(current.model_fields)
    return []


def _model_in(annotation: Any) -> Any:
    from pydantic import BaseModel

    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in getattr(annotation, "__args__", ()) or ():
        found = _model_in(arg)
        if found is not None:
            return found
    return None


def parse_robot_text(text: str, *, file: str = ROBOT_FILE, project: Path | None = None) -> Robot:
    """Parse and validate robot.yaml text; ``project`` enables the file-system checks."""
    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
        line = mark.line + 1 if mark is not None else None
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ConfigError([Problem(file, line, "", f"YAML syntax error: {problem}")]) from None
    if node is None:
        raise ConfigError([Problem(file, None, "", "file is empty; see 'robocore schema' for its keys")])
    lines = LineMap()
    lines.add(node)
    try:
        data = yaml.safe_load(text)
    except (yaml.YAMLError, ValueError, TypeError, RecursionError) as exc:
        raise ConfigError([Problem(file, None, "", f"YAML could not be read: {exc}")]) from None
    if not isinstance(data, dict):
        raise ConfigError([Problem(file, 1, "", "top level must be a mapping of keys (ros_distro, hosts, components, ...)")])
    bad_keys = [k for k in data if not isinstance(k, str)]
    problems: list[Problem] = [
        Problem(file, lines.line_of(path), format_path(path), "this key appears twice") for path, _ in lines.duplicates
    ]
    problems += [Problem(file, lines.line_of(()), repr(k), "keys must be strings") for k in bad_keys]
    if problems:
        raise ConfigError(problems)
    try:
        robot = Robot.model_validate(data)
    except ValidationError as exc:
        for error in exc.errors():
            loc = tuple(error["loc"])
            message = _friendly(dict(error))
            if error.get("type") == "extra_forbidden":
                allowed = _allowed_keys(Robot, loc)
                if allowed:
                    message += f" (allowed: {', '.join(allowed)})"
            problems.append(Problem(file, lines.line_of(loc), format_path(loc), message))
        raise ConfigError(problems) from None
    problems = [
        Problem(file, lines.line_of(path), format_path(path), message)
        for path, message in check_robot(robot, project)
    ]
    if problems:
        raise ConfigError(problems)
    return robot


def load_robot(project: Path, *, file_name: str = ROBOT_FILE) -> Robot:
    """Load ``project/robot.yaml``; raise :class:`ConfigError` naming every problem."""
    path = project / file_name
    shown = str(path)
    if not project.is_dir():
        raise ConfigError([Problem(str(project), None, "", "project folder does not exist")])
    if not path.is_file():
        raise ConfigError([Problem(shown, None, "", "file not found (is this a robocore project? 'robocore init DIR' makes one)")])
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError([Problem(shown, None, "", f"cannot read file: {exc}")]) from None
    return parse_robot_text(text, file=shown, project=project)
