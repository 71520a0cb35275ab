"""init: a new robot project from the copier template.

A thin wrapper around ``copier copy``: it fills in what copier cannot know (this machine's
user and architecture as the default host, where CI installs robocore from), chooses the
template source so that ``copier update`` works later (:func:`choose_template`), refuses to
write into a folder that holds something else, writes the JSON Schema the generated robot.yaml
points editors at, and checks the result with robocore's own loader.
"""

from __future__ import annotations

import getpass
import os
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from robocore.adapters import origin
from robocore.commands.support.reporting import Reporter
from robocore.config.generations import base_problem
from robocore.config.model import Arch, BaseKind, RosDistro
from robocore.errors import UsageError
from robocore.project import ProjectFolder, this_machine_arch
from robocore.ui import shown

#: Where the generated robot.yaml's ``yaml-language-server`` comment points (relative to the project).


@dataclass(frozen=True)
class TemplateChoice:
    """Where init renders the template from, and what the project records about it."""

    location: str
    """What copier copies: a git URL, a local git repository, or a template folder."""
    ref: str | None
    """The git tag or commit to render (None: a plain folder, or copier's default, the latest tag)."""
    versioned: bool
    """The project records a template version (``_commit``), so ``copier update`` can work."""
    data: dict[str, str] = field(default_factory=dict)
    """Answers init fills in: ``robocore_repository`` (and ``robocore_ref`` for the bundled template)."""
    note: str = ""
    """One line for the user about updates."""


def default_arch() -> str:
    """The arch of the default host: this machine's (Docker's name), or amd64 when robocore has no image for it."""
    arch = this_machine_arch()
    return arch if arch in {a.value for a in Arch} else "amd64"


def current_user() -> str:
    """The user running robocore (the default SSH user of the default host)."""
    try:
        return getpass.getuser()
    except (KeyError, OSError):
        return "root"


def default_hosts() -> list[dict[str, str]]:
    """The default host list: just this machine."""
    return [{"name": "devmachine", "ip": "127.0.0.1", "user": current_user(), "arch": default_arch()}]


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
    from robocore.files import path_kind

    kind, reason = path_kind(path)
    if kind == "unusable":  # a name too long, a NUL, no permission: one line, never a traceback
        raise UsageError(f"{shown(str(path))}: cannot be used as the project folder: {reason}")
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


def choose_template(source: str | None, ref: str | None) -> TemplateChoice:
    """Decide what init renders: an explicit source, robocore's own git repository at its tag, or the bundled copy.

    1. ``--source`` (else ``$ROBOCORE_TEMPLATE``): that git URL, git repository or folder, at
       ``--ref`` (copier's default without it: the latest tag).
    2. Else robocore's own repository at ``--ref`` or the version tag ``v<version>``: the source
       checkout robocore runs from (editable install), then the folder pip installed it from, then
       the git URL pip installed it from (``pip install git+URL@TAG``, checked with ``git ls-remote``);
       the first that has the tag (and, locally, the template files at it) wins.
    3. Else the template bundled with robocore; the project then records no version.
    """
    from robocore.adapters import copier_adapter

    if ref is not None and not origin.REF_PATTERN.fullmatch(ref):
        raise UsageError(f"--ref {ref!r}: not a git tag, branch or commit name")
    explicit = source or os.environ.get(copier_adapter.TEMPLATE_ENV)
    if explicit:
        return _explicit_template(explicit, ref, "--source" if source else copier_adapter.TEMPLATE_ENV)
    tag = ref or origin.version_tag()
    installed = origin.installation()
    for folder in (origin.source_checkout(), installed.folder):
        if folder is not None and origin.has_template_at(folder, tag):
            return _git_template(str(folder), tag, _repository_of(folder))
    if installed.vcs_url and origin.remote_has_tag(installed.vcs_url, tag):
        return _git_template(f"git+{installed.vcs_url}", tag, origin.pip_url(installed.vcs_url) or "")
    if ref is not None:
        raise UsageError(f"--ref {ref}: no git repository of robocore with it was found",
                         hint="name the repository: --source PATH_OR_GIT_URL")
    repository = origin.pip_url(installed.vcs_url) if installed.vcs_url else None
    data = {"robocore_repository": repository or "", "robocore_ref": installed.commit or tag}
    return TemplateChoice(
        location=str(copier_adapter.bundled_template()), ref=None, versioned=False, data=data,
        note=f"note: no git repository of robocore with tag {tag} was found, so the bundled template was rendered "
             f"and copier update needs _src_path: <robocore's git URL> and _commit: {tag} in .copier-answers.yml",
    )


def _explicit_template(location: str, ref: str | None, flag: str) -> TemplateChoice:
    if location.startswith("-"):
        raise UsageError(f"{flag} {location!r}: not a path or git URL")
    if origin.is_url(location):
        for_copier = location if location.startswith(("git+", "gh:", "gl:")) else f"git+{location}"
        return _git_template(for_copier, ref, origin.pip_url(location) or "")
    folder = Path(location).expanduser().absolute()
    if not folder.is_dir():
        raise UsageError(f"{flag} {location}: no such folder", hint="a robocore repository (path or git URL)")
    if origin.is_repository_root(folder):
        return _git_template(str(folder), ref, _repository_of(folder))
    if ref is not None:
        raise UsageError(f"--ref {ref}: {folder} is not a git repository, so it has no versions")
    return TemplateChoice(location=str(folder), ref=None, versioned=False,
                          note=f"note: {folder} is a plain folder: the project records no template version "
                               "and copier update will not work")


def _git_template(location: str, ref: str | None, repository: str) -> TemplateChoice:
    note = f"template: {location} at {ref or 'its latest tag'}; copier update brings later versions"
    return TemplateChoice(location=location, ref=ref, versioned=True, data={"robocore_repository": repository},
                          note=note)


def _repository_of(folder: Path) -> str:
    """Where CI installs robocore from for a local repository: its origin when that is remote, else the folder."""
    remote = origin.origin_url(folder)
    url = origin.pip_url(remote) if remote and origin.is_url(remote) else None
    return url or folder.as_uri()


def run(path: Path, *, defaults: bool, distro: str | None, base: str | None, dry_run: bool,
        source: str | None = None, ref: str | None = None, report: Reporter | None = None) -> None:
    """Render the template into ``path``; with an existing project, only add missing files."""
    from robocore.adapters import copier_adapter

    report = report or Reporter("init")

    if str(path).startswith("-"):
        raise UsageError(f"{path}: not a project folder (it starts with '-')",
                         hint="robocore --help init lists init's options; write ./-name for such a folder")
    destination = path.expanduser().absolute()
    data: dict[str, Any] = {}
    if (value := _choice(distro, RosDistro, "--distro")) is not None:
        data["ros_distro"] = value
    if (value := _choice(base, BaseKind, "--base")) is not None:
        data["base_kind"] = value
    wanted = (data.get("ros_distro", RosDistro.jazzy.value), data.get("base_kind", BaseKind.official.value))
    if (problem := base_problem(*wanted, setting="--base ")) is not None:
        raise UsageError(f"--distro {wanted[0]} --base {wanted[1]}: {problem}")
    existing = check_destination(destination)
    if not defaults and not sys.stdin.isatty():
        raise UsageError(
            "init asks questions but stdin is not a terminal",
            hint="add --defaults to take every default (with --distro/--base to choose those)",
        )
    template = choose_template(source, ref)
    if existing:
        report.notice(f"{destination}: existing robocore project; only missing template files are added")
        if data:
            report.notice("note: robot.yaml is kept as it is; change ros_distro or base.kind in it yourself")
    request = copier_adapter.CopyRequest(
        template=template.location,
        destination=destination,
        data={**template.data, **data},
        user_defaults={"project_name": project_name(destination), "hosts": default_hosts()},
        defaults=defaults,
        pretend=dry_run,
        keep_existing=existing,
        vcs_ref=template.ref,
    )
    copier_adapter.copy(request)
    report.notice(template.note)
    if dry_run:
        folder = ProjectFolder(destination)
        report.notice(f"would write {folder.schema_file}, {folder.fleet_schema_file.name} and check "
                      f"{folder.robot_file}")
        return
    _write_schema(destination)
    _check(destination, report)


def _write_schema(project: Path) -> None:
    from robocore.config.schema import schema_json
    from robocore.files import write_atomic

    folder = ProjectFolder(project)
    write_atomic(folder.schema_file, schema_json() + "\n")
    write_atomic(folder.fleet_schema_file, schema_json(fleet=True) + "\n")


def _check(project: Path, report: Reporter) -> None:
    from robocore.config.loader import load_robot

    robot = load_robot(project)
    report.notice(
        f"{ProjectFolder(project).robot_file}: ok — {robot.generation} {robot.ros_distro.value}, "
        f"base {robot.base.kind.value}, "
        f"{len(robot.hosts)} host(s), {len(robot.components)} component(s)"
    )
