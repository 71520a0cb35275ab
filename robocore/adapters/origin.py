"""Where this robocore came from: a source checkout, a git URL pip installed it from, or neither.

robocore's repository is also its project template (the root ``copier.yml`` renders
``template/``). A project rendered from that repository at robocore's version tag records the
repository and the tag in its ``.copier-answers.yml``, which is what ``copier update`` needs to
fetch the old and the new template. This module answers the questions that choice depends on:
what pip recorded about the installation (PEP 610's ``direct_url.json``), and what git says
about a repository (is it one, does it hold the tag and the template at that tag, where is its
origin). Every git call is an argv list with a time limit, never asks for credentials, and
treats a failure as "no".
"""

from __future__ import annotations

import json
import os
import re
import subprocess
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlparse
from urllib.request import url2pathname

import robocore

#: The files that make a tree robocore's repository (the template at the root and in template/).
TEMPLATE_FILES = ("copier.yml", "template/copier.yml")

#: A git tag, branch or commit robocore passes to git and copier (never an option: no leading '-').
REF_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9._/+-]*")

#: A repository URL the template accepts for CI (it is written into CI files): the template's own validator.
CI_URL_PATTERN = re.compile(r"(https?|ssh|git|file)://[A-Za-z0-9._~:/@%+-]+")

#: scp-like git addresses: ``git@github.com:org/robocore.git``.
_SCP_LIKE = re.compile(r"(?P<user>[A-Za-z0-9._-]+)@(?P<host>[A-Za-z0-9._-]+):(?P<path>(?!//).+)")
_SCHEME = re.compile(r"[a-z][a-z0-9+.-]*://")
_SHORTCUTS = {"gh:": "https://github.com/", "gl:": "https://gitlab.com/"}
_GIT_TIMEOUT = 30.0


def version_tag() -> str:
    """The git tag of the running robocore's version: ``v`` + ``robocore.__version__`` (v0.1.0)."""
    return f"v{robocore.__version__}"


@dataclass(frozen=True)
class Installation:
    """What pip recorded about where robocore was installed from (PEP 610)."""

    vcs_url: str | None = None
    """The git URL of ``pip install git+URL@REF``, without the ``git+`` and the ``@REF``."""
    commit: str | None = None
    """The commit pip installed from ``vcs_url``."""
    folder: Path | None = None
    """The local folder of ``pip install [-e] PATH``."""


def installation(distribution: str = "robocore") -> Installation:
    """Read ``direct_url.json`` of the installed distribution; an empty record when there is none."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import distribution as find

    try:
        text = find(distribution).read_text("direct_url.json")
    except PackageNotFoundError:
        return Installation()
    return parse_direct_url(text)


def parse_direct_url(text: str | None) -> Installation:
    """The parts of a PEP 610 ``direct_url.json`` document robocore uses (garbage gives nothing)."""
    try:
        record = json.loads(text) if text else None
    except ValueError:
        return Installation()
    if not isinstance(record, dict) or not isinstance(url := record.get("url"), str):
        return Installation()
    vcs = record.get("vcs_info")
    if isinstance(vcs, dict) and vcs.get("vcs") == "git":
        commit = vcs.get("commit_id")
        return Installation(vcs_url=url, commit=commit if isinstance(commit, str) else None)
    if isinstance(record.get("dir_info"), dict) and urlparse(url).scheme == "file":
        return Installation(folder=Path(url2pathname(urlparse(url).path)))
    return Installation()


def source_checkout() -> Path | None:
    """The folder holding the imported robocore package when it is robocore's repository (editable installs)."""
    folder = Path(robocore.__file__).resolve().parent.parent
    return folder if all((folder / name).is_file() for name in TEMPLATE_FILES) else None


def _git(args: list[str], cwd: Path | None = None) -> subprocess.CompletedProcess[str] | None:
    env = {**os.environ, "GIT_TERMINAL_PROMPT": "0", "GIT_ASKPASS": "true", "SSH_ASKPASS": "true"}
    try:
        return subprocess.run(["git", *args], cwd=cwd, env=env, capture_output=True, text=True, check=False,
                              timeout=_GIT_TIMEOUT, stdin=subprocess.DEVNULL)
    except (OSError, subprocess.TimeoutExpired):
        return None


def is_repository_root(folder: Path) -> bool:
    """True when ``folder`` is the top of a git work tree (copier only treats such a folder as git)."""
    done = _git(["rev-parse", "--show-toplevel"], cwd=folder) if folder.is_dir() else None
    return done is not None and done.returncode == 0 and Path(done.stdout.strip()).resolve() == folder.resolve()


def has_template_at(repository: Path, ref: str) -> bool:
    """True when the git repository ``repository`` has ``ref`` and robocore's template files at it."""
    if not REF_PATTERN.fullmatch(ref) or not is_repository_root(repository):
        return False
    for name in TEMPLATE_FILES:
        done = _git(["cat-file", "-e", f"{ref}:{name}"], cwd=repository)
        if done is None or done.returncode != 0:
            return False
    return True


def remote_has_tag(url: str, tag: str) -> bool:
    """True when the git repository at ``url`` answers and lists ``tag`` (one ``git ls-remote``)."""
    if not REF_PATTERN.fullmatch(tag) or url.startswith("-"):
        return False
    done = _git(["ls-remote", "--tags", "--", url, f"refs/tags/{tag}"])
    return done is not None and done.returncode == 0 and f"refs/tags/{tag}" in done.stdout


def origin_url(repository: Path) -> str | None:
    """The URL of the ``origin`` remote of a local repository, if it has one."""
    done = _git(["config", "--get", "remote.origin.url"], cwd=repository)
    url = done.stdout.strip() if done is not None and done.returncode == 0 else ""
    return url or None


def pip_url(location: str) -> str | None:
    """``location`` as a URL pip installs from with ``git+``, of :data:`CI_URL_PATTERN`; None if it is none.

    Accepts what copier accepts as a template address: a URL (with or without ``git+``), the
    ``gh:``/``gl:`` shortcuts, an scp-like ``user@host:path`` and an absolute local path.
    """
    url = location.removeprefix("git+")
    shortcut = next((s for s in _SHORTCUTS if url.startswith(s)), None)
    scp = _SCP_LIKE.fullmatch(url)
    if shortcut:
        url = _SHORTCUTS[shortcut] + url[len(shortcut):]
    elif scp:
        url = f"ssh://{scp['user']}@{scp['host']}/{scp['path']}"
    elif url.startswith("/"):
        url = Path(url).as_uri()
    return url if CI_URL_PATTERN.fullmatch(url) else None


def is_url(location: str) -> bool:
    """True when ``location`` is a remote template address rather than a local path."""
    return location.startswith(("git+", *_SHORTCUTS)) or bool(_SCHEME.match(location) or _SCP_LIKE.fullmatch(location))
