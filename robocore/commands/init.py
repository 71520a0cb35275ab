"""init: a new robot project from the copier template.

A thin wrapper around ``copier copy``: it fills in what copier cannot know (this machine's
user and architecture as the default host), refuses to write into a folder that holds
something else, writes the JSON Schema the generated robot.yaml points editors at, and
checks the result with robocore's own loader.
"""

from __future__ import annotations

import getpass
import platform
import re
import sys
from pathlib import Path
from typing import Any

from robocore.config.model import Arch, BaseKind, RosDistro, docker_arch
from robocore.errors import UsageError

#: Where the generated robot.yaml's ``yaml-language-server`` comment points (relative to the project).
SCHEMA_FILE = Path(".robocore") / "robot.schema.json"

def machine_arch() -> str:
    """This machine's architecture as a Docker platform name (amd64 when robocore has no name for it)."""
    arch = docker_arch(platform.machine())
    return arch if arch in {a.value for a in Arch} else "amd64"


def current_user() -> str:
    """The user running robocore (the default SSH user of the default host)."""
    try:
        return getpass.getuser()
    except (KeyError, OSError):
        return "root"


def default_hosts() -> list[dict[str, str]]:
    """The default host list: just this machine."""
    return [{"name": "devmachine", "ip": "127.0.0.1", "user": current_user(), "arch": machine_arch()}]


def project_name(destination: Path) -> str:
    """The default project name: the folder name, with characters the template refuses replaced by '-'."""
    name = re.sub(r"[^A-Za-z0-9_.-]+", "-", destination.name).strip("-._")
    return name[:63] or "robot"


def _choice(value: str | None, allowed: type[RosDistro] | type[BaseKind], flag: str) -> str | None:
    if value is None:
        return None
    names = [member.value for member in allowed]
    if value not in names:
        raise UsageError(f"{flag} {value!r}: unknown (choose from {', '.join(names)})")
    return value


def check_destination(path: Path) -> bool:
    """Refuse a folder that is not empty and not a robocore project; True when it is an existing project."""
    if path.exists() and not path.is_dir():
        raise UsageError(f"{path}: exists and is not a folder", hint="choose a new or empty folder")
    if not path.is_dir() or not any(path.iterdir()):
        return False
    if (path / "robot.yaml").is_file():
        return True
    raise UsageError(
        f"{path}: folder is not empty and is not a robocore project (no robot.yaml)",
        hint="choose a new or empty folder",
    )


def run(path: Path, *, defaults: bool, distro: str | None, base: str | None, dry_run: bool) -> None:
    """Render the template into ``path``; with an existing project, only add missing files."""
    from robocore.adapters import copier_adapter
    from robocore.ui import console

    destination = path.expanduser().absolute()
    data: dict[str, Any] = {}
    if (value := _choice(distro, RosDistro, "--distro")) is not None:
        data["ros_distro"] = value
    if (value := _choice(base, BaseKind, "--base")) is not None:
        data["base_kind"] = value
    existing = check_destination(destination)
    if not defaults and not sys.stdin.isatty():
        raise UsageError(
            "init asks questions but stdin is not a terminal",
            hint="add --defaults to take every default (with --distro/--base to choose those)",
        )
    if existing:
        console().print(f"{destination}: existing robocore project; only missing template files are added",
                        markup=False)
        if data:
            console().print("note: robot.yaml is kept as it is; change ros_distro or base.kind in it yourself")
    request = copier_adapter.CopyRequest(
        template=copier_adapter.template_source(),
        destination=destination,
        data=data,
        user_defaults={"project_name": project_name(destination), "hosts": default_hosts()},
        defaults=defaults,
        pretend=dry_run,
        keep_existing=existing,
    )
    copier_adapter.copy(request)
    if dry_run:
        console().print(f"would write {destination / SCHEMA_FILE} and check {destination / 'robot.yaml'}",
                        markup=False)
        return
    _write_schema(destination)
    _check(destination)


def _write_schema(project: Path) -> None:
    from robocore.config.schema import schema_json
    from robocore.files import write_atomic

    write_atomic(project / SCHEMA_FILE, schema_json() + "\n")


def _check(project: Path) -> None:
    from robocore.config.loader import load_robot
    from robocore.ui import console

    robot = load_robot(project)
    console().print(
        f"{project / 'robot.yaml'}: ok — ROS 2 {robot.ros_distro.value}, base {robot.base.kind.value}, "
        f"{len(robot.hosts)} host(s), {len(robot.components)} component(s)"
    )
