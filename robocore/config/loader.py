"""Load robot.yaml into a :class:`~robocore.config.model.Robot`, or fail with every problem.

The YAML is composed into nodes first so that each key path can be traced back to its
line. Field errors (pydantic), duplicate keys and the cross-field checks are reported
together, one line each, sorted by line, as
``robot.yaml:14: components[0].runs_on: unknown host 'rpi6' (known: rpi5)``. When some
fields are invalid the cross-field checks still run on the parts that validated.
"""

from __future__ import annotations

import contextlib
import os
import re
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ValidationError

from robocore.config.checks import check_parts, check_robot, salvage
from robocore.config.hints import MAX_SUGGESTIONS, did_you_mean
from robocore.config.model import Host, Robot
from robocore.config.risks import risky_settings
from robocore.config.values import shown as shown
from robocore.config.yamltext import MAX_FILE_BYTES as MAX_FILE_BYTES
from robocore.config.yamltext import ROBOT_FILE as ROBOT_FILE
from robocore.config.yamltext import KeyPath, LineMap, problem, read_yaml, too_big
from robocore.errors import ConfigError, Problem, UnsafePath
from robocore.files import path_kind, read_project_file

#: Problems reported one per line; the rest are counted in a last line.
MAX_PROBLEMS = 200

_PLAIN_KEY = re.compile(r"^[A-Za-z0-9_\-.]+$")


def format_path(path: Iterable[object]) -> str:
    """Render a key path the way users write it: ``components[0].runs_on``."""
    out = ""
    for part in path:
        if isinstance(part, int) and not isinstance(part, bool):
            out += f"[{part}]"
        elif isinstance(part, str) and _PLAIN_KEY.match(part):
            out += f".{part}" if out else part
        else:
            out += f"[{shown(part)}]"
    return out


# --- pydantic errors as user messages ----------------------------------------------------------

ErrorDict = dict[str, Any]

_EXPECTED = {
    "string_type": "a string",
    "int_type": "a whole number",
    "int_parsing": "a whole number",
    "int_from_float": "a whole number",
    "float_type": "a number",
    "float_parsing": "a number",
    "bool_type": "true or false",
    "bool_parsing": "true or false",
    "list_type": "a list",
    "dict_type": "a mapping of keys",
    "model_type": "a mapping of keys",
    "model_attributes_type": "a mapping of keys",
}

_LIMITS = {
    "greater_than": ("gt", "greater than"),
    "greater_than_equal": ("ge", "at least"),
    "less_than": ("lt", "less than"),
    "less_than_equal": ("le", "at most"),
}


def _kind_of(value: object) -> str:
    if value is None:
        return "nothing (null)"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        return "a list"
    return shown(value)


def _friendly(error: ErrorDict, *, suggest: bool = True) -> str:
    kind = str(error.get("type", ""))
    ctx = error.get("ctx") or {}
    value = error.get("input")
    loc = tuple(error.get("loc", ()))
    if kind == "missing":
        return "required key is missing"
    if kind == "extra_forbidden":
        return f"unknown key {shown(loc[-1]) if loc else ''}".rstrip()
    if kind in ("invalid_key",):
        return f"keys must be text, not {shown(value)}"
    if kind in ("enum", "literal_error"):
        expected = str(ctx.get("expected", "")).replace(" or ", ", ").replace("'", "")
        hint = did_you_mean(str(value), expected.split(", ")) if suggest else ""
        return f"{shown(value)} is not one of: {expected}{hint}"
    if kind == "string_pattern_mismatch":
        pattern = str(ctx.get("pattern", "?"))
        return f"{shown(value)} is not a valid value here (expected to match {pattern})"
    if kind == "too_short" and isinstance(value, list):
        return f"needs at least {ctx.get('min_length', 1)} item(s)"
    if kind in ("string_too_short", "too_short"):
        return f"{shown(value)} is too short (at least {ctx.get('min_length', 1)})"
    if kind in ("string_too_long", "too_long"):
        return f"value is too long (at most {ctx.get('max_length', '?')})"
    if kind in _LIMITS:
        key, words = _LIMITS[kind]
        return f"{shown(value)} is out of range (must be {words} {ctx.get(key)})"
    if kind in _EXPECTED:
        message = f"expected {_EXPECTED[kind]}, got {_kind_of(value)}"
        if kind == "string_type" and isinstance(value, (int, float, bool)):
            message += " (quote it to keep it as text)"
        if kind == "list_type" and isinstance(value, str):
            message += f" (write it as [{value}] or as '- {value}' lines)"
        return message
    msg = str(error.get("msg", "invalid value"))
    if msg.startswith("Value error, "):
        msg = msg[len("Value error, "):]
    return msg[:1].lower() + msg[1:]


def _allowed_keys(model: type[BaseModel], loc: Sequence[str | int]) -> list[str]:
    """The keys allowed at the mapping that contains ``loc`` (for 'unknown key' hints)."""
    current: type[BaseModel] | None = model
    for part in loc[:-1]:
        if isinstance(part, int) or current is None:
            continue
        fields = current.model_fields
        if part not in fields:
            return []
        current = _model_in(fields[part].annotation)
    return sorted(f.alias or name for name, f in current.model_fields.items()) if current is not None else []


def _model_in(annotation: Any) -> type[BaseModel] | None:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in getattr(annotation, "__args__", ()) or ():
        found = _model_in(arg)
        if found is not None:
            return found
    return None


def field_problems(exc: ValidationError, file: str, lines: LineMap, model: type[BaseModel] = Robot) -> list[Problem]:
    """One problem per pydantic error of ``model`` (robot.yaml's :class:`Robot`, or another file's top model);
    only the first :data:`MAX_SUGGESTIONS` get a "did you mean"."""
    problems: list[Problem] = []
    for count, error in enumerate(exc.errors()):
        suggest = count < MAX_SUGGESTIONS
        loc = tuple(part for part in error["loc"] if part != "[key]")
        message = _friendly(dict(error), suggest=suggest)
        if error.get("type") == "extra_forbidden":
            allowed = _allowed_keys(model, loc)
            if allowed:
                hint = did_you_mean(str(loc[-1]), allowed) if suggest else ""
                message += hint + f" (allowed: {', '.join(allowed)})"
        problems.append(problem(file, lines.line_of(loc), format_path(loc), message))
    return problems


# --- loading -----------------------------------------------------------------------------------


def parse_robot_text(text: str, *, file: str = ROBOT_FILE, project: Path | None = None) -> Robot:
    """Parse and validate robot.yaml text; ``project`` enables the file-system checks.

    Raises :class:`ConfigError` with every problem found, sorted by line.
    """
    data, lines = read_yaml(text, file)
    if not isinstance(data, dict):
        raise not_a_mapping(data, lines, file, "ros_distro, hosts, components, ...")
    problems = [problem(file, line, format_path(path), "this key appears twice") for path, line in lines.duplicates]
    robot: Robot | None
    try:
        robot = Robot.model_validate(data)
    except ValidationError as exc:
        robot = None
        problems += field_problems(exc, file, lines)
    except RecursionError:
        raise ConfigError([problem(file, None, "", "YAML is nested too deeply")]) from None
    found = check_robot(robot, project) if robot is not None else check_parts(salvage(data), project)
    problems += [problem(file, lines.line_of(path), format_path(path), message) for path, message in found]
    if problems:
        raise ConfigError(ordered(problems))
    assert robot is not None
    return robot


def not_a_mapping(data: object, lines: LineMap, file: str, keys: str) -> ConfigError:
    """The one-line refusal of a file whose top level is not a mapping (``keys``: the keys it should hold)."""
    return ConfigError([
        problem(file, lines.line_of(()), "", f"top level must be a mapping of keys ({keys}), got {_kind_of(data)}")])


def ordered(problems: list[Problem]) -> list[Problem]:
    """Problems without repeats, sorted by line; past :data:`MAX_PROBLEMS`, one last line counts the rest."""
    unique = sorted(dict.fromkeys(problems), key=lambda p: p.line if p.line is not None else 0)
    if len(unique) <= MAX_PROBLEMS:
        return unique
    rest = len(unique) - MAX_PROBLEMS
    return [*unique[:MAX_PROBLEMS], problem(unique[0].file, None, "", f"... and {rest} more problems")]


def display_path(path: Path) -> str:
    """``path`` relative to the current folder when it is inside it, else as given."""
    try:
        rel = os.path.relpath(path)
    except ValueError:
        return str(path)
    return rel if not rel.startswith("..") else str(path)


def load_robot(project: Path, *, file_name: str = ROBOT_FILE) -> Robot:
    """Load ``project/robot.yaml``; raise :class:`ConfigError` naming every problem."""
    text, shown_path = read_config_file(project, file_name, schema_hint="robocore schema")
    return parse_robot_text(text, file=shown_path, project=project)


def read_config_file(project: Path, file_name: str, *, schema_hint: str) -> tuple[str, str]:
    """The text of ``project/file_name`` (robot.yaml, fleet.yaml) and the path to show in messages, read under the
    rules every robocore input file obeys: the project must be a folder; the file a regular file inside the project
    (a link out of it, a FIFO or a device is one line at once, never a blocked read); at most
    :data:`MAX_FILE_BYTES`; UTF-8; not empty (``schema_hint`` is the command that prints its keys).
    Raises :class:`ConfigError` with one problem."""
    path = project / file_name
    shown_path = display_path(path)
    folder, reason = path_kind(project)
    if folder != "dir":
        what = {"file": "is a file, not a project folder", "missing": "project folder does not exist"}.get(
            folder, f"cannot be used as a project folder: {reason}")
        raise ConfigError([problem(display_path(project), None, "", what)])
    kind, reason = path_kind(path)
    if kind != "file":
        what = {"dir": "is not a file", "unusable": f"cannot be read: {reason}"}.get(
            kind, "file not found (is this a robocore project? 'robocore init DIR' makes one)")
        raise ConfigError([problem(shown_path, None, "", what)])
    try:  # a link out of the project, a FIFO or a device: one line at once, never a blocked read
        raw = read_project_file(path, project, limit=MAX_FILE_BYTES, what=file_name)
    except UnsafePath as exc:
        raise ConfigError([problem(shown_path, None, "", str(exc).split(": ", 1)[-1])]) from None
    except OSError as exc:
        raise ConfigError([problem(shown_path, None, "", f"cannot read file: {exc.strerror or exc}")]) from None
    if len(raw) > MAX_FILE_BYTES:
        raise too_big(os.stat(path).st_size, shown_path, file_name)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError([problem(shown_path, None, "", f"not UTF-8 text (byte {exc.start})")]) from None
    if not text.strip():
        raise ConfigError([problem(shown_path, None, "", f"file is empty; see '{schema_hint}' for its keys")])
    return text, shown_path


def located(path: Path, found: Iterable[tuple[KeyPath, str]]) -> ConfigError:
    """A ConfigError for problems found after loading (``(key path, message)`` pairs), each with its line in ``path``.

    For checks that live outside the config package (e.g. what the wheels base can build);
    lines are omitted when the file cannot be read again.
    """
    shown_path = display_path(path)
    lines = _lines_of(path, shown_path)
    return ConfigError(ordered([problem(shown_path, lines.line_of(p), format_path(p), m) for p, m in found]))


def _lines_of(path: Path, shown_path: str) -> LineMap:
    lines = LineMap()
    with contextlib.suppress(OSError, UnicodeDecodeError, ConfigError):
        _, lines = read_yaml(path.read_text(encoding="utf-8"), shown_path)
    return lines


def robot_warnings(path: Path, robot: Robot, project: Path | None = None) -> list[Problem]:
    """One warning per dangerous but allowed setting of ``robot`` (privileged, the host's root or Docker
    socket mounted, disks as devices, ...), each with its line in ``path``, so that a reviewer sees them.

    ``project`` (the project folder) adds the checks that look at files (volumes that leave the project).
    """
    found = risky_settings(robot, project.resolve() if project is not None else None)
    if not found:
        return []
    shown_path = display_path(path)
    lines = _lines_of(path, shown_path)
    warnings = [problem(shown_path, lines.line_of(p), format_path(p), m, severity="warning") for p, m in found]
    return sorted(dict.fromkeys(warnings), key=lambda p: p.line if p.line is not None else 0)


def fleet_warnings(path: Path, manager: Host | None, domains: Sequence[int | None] = (),
                   ros_version: int = 2) -> list[Problem]:
    """One warning per dangerous but allowed setting of fleet.yaml (its ``manager`` reached by plain TCP, a robot's
    own ROS 2 domain in the ephemeral port range: ``domains`` are the robots' ``ros_domain_id`` in file order), each
    with its line in ``path``, as :func:`robot_warnings` gives robot.yaml's."""
    from robocore.config.risks import EPHEMERAL_SAFE_DOMAIN, ephemeral_domain, host_risks

    found = [(("manager", *key), message) for key, message in host_risks(manager)] if manager is not None else []
    if ros_version == 2:
        found += [(("robots", index, "ros_domain_id"), ephemeral_domain(domain)) for index, domain in enumerate(domains)
                  if domain is not None and domain > EPHEMERAL_SAFE_DOMAIN]
    return located_warnings(path, found)


def located_warnings(path: Path, found: Sequence[tuple[KeyPath, str]]) -> list[Problem]:
    """Warnings found after loading (``(key path, message)`` pairs), each with its line in ``path``, as
    :func:`located` gives errors."""
    if not found:
        return []
    shown_path = display_path(path)
    lines = _lines_of(path, shown_path)
    return [problem(shown_path, lines.line_of(p), format_path(p), m, severity="warning") for p, m in found]


def fleet_model_warnings(path: Path, robot: Robot, fleet_users: dict[str, bool]) -> list[Problem]:
    """One warning per host of robot.yaml (at ``path``) that is this machine (a loopback address: the template's dev
    host) while a fleet file makes robot.yaml the model of many robots: each robot then gets a host of that name at
    its own address, running what ``runs_on`` it, and reached as robot.yaml's user there unless the fleet file
    gives one (``fleet_users``: host name -> every robot of the fleet names its user)."""
    found = []
    for index, host in enumerate(robot.hosts):
        if not host.is_loopback:
            continue
        user = "" if fleet_users.get(host.name) else f", reached as robot.yaml's user {host.user} there"
        found.append((("hosts", index, "ip"), f"{host.name} is this machine ({host.ip}), a dev host, while fleet.yaml "
                      f"makes robot.yaml the model of every robot: each robot gets a host {host.name} at its own "
                      f"address{user}; name the hosts after the robot's computers (main) and keep dev-only "
                      "components out of the model"))
    if not found:
        return []
    shown_path = display_path(path)
    lines = _lines_of(path, shown_path)
    return [problem(shown_path, lines.line_of(p), format_path(p), m, severity="warning") for p, m in found]

