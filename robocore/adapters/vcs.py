"""Git checkouts fetched on the dev machine (repositories and common packages), vcstool's .repos format.

A checkout is cached under ``.robocore/cache/git/<key>`` and reused as long as its URL and
version are unchanged; ``refresh=True`` fetches again (moving branches).

robot.yaml's URL and version never reach git as options: the version must be a valid ref name
(:func:`check_version`, git's own ``check-ref-format`` rules) and both follow ``--end-of-options``.
Every fetch runs with :func:`git_config`: only the network transports (https, ssh, http, git) are
allowed, so a URL cannot run a command (``ext::``) or read this machine's own repositories
(``file://``, a path) unless its robot.yaml entry opts in (``allow_protocol: ext`` or ``file``).
"""

from __future__ import annotations

import hashlib
import json
import re
import shutil
import subprocess
from collections.abc import Sequence
from pathlib import Path

from robocore.config.model import Repository
from robocore.errors import BuildError, ToolMissing, UsageError
from robocore.files import make_folder, remove_tree, write_atomic

SOURCE_FILE = "robocore-source"
#: Transports git may use to fetch robot.yaml's repositories without an opt-in.
NETWORK_PROTOCOLS = ("https", "ssh", "http", "git")
#: Transports only an entry's ``allow_protocol`` opens: ext:: runs a command, file reads this machine's files.
LOCAL_PROTOCOLS = ("ext", "file")
#: What git's check-ref-format refuses anywhere in a ref name (with --allow-onelevel).
_BAD_REF = re.compile(r"[\x00-\x20\x7f~^:?*\[\\]|\.\.|@\{|//|/\.|\.lock(/|$)|^[./-]|[/.]$")


def git_config(*, allow_protocol: str | None = None) -> list[str]:
    """``-c`` settings of a fetch: transports limited to :data:`NETWORK_PROTOCOLS`; ``ext::`` and local
    repositories (``file://`` and paths) refused unless ``allow_protocol`` (robot.yaml's opt-in of the
    entry) names them."""
    argv = ["-c", "protocol.allow=never"]
    for name in NETWORK_PROTOCOLS:
        argv += ["-c", f"protocol.{name}.allow=always"]
    for name in LOCAL_PROTOCOLS:
        argv += ["-c", f"protocol.{name}.allow={'always' if allow_protocol == name else 'never'}"]
    return argv


def check_version(version: str) -> None:
    """Raise UsageError unless ``version`` is a valid branch, tag or commit name (git's check-ref-format
    rules with ``--allow-onelevel``; a leading ``-`` is refused too: git would read it as an option)."""
    if not version or version == "@" or _BAD_REF.search(version):
        raise UsageError(f"git: {version!r} is not a valid branch, tag or commit name",
                         hint="fix the version (or branch) in robot.yaml")


def check_url(url: str) -> None:
    """Raise UsageError for a URL git would read as an option or that holds control characters."""
    if not url or url.startswith("-") or any(ord(ch) < 0x20 or ord(ch) == 0x7F for ch in url):
        raise UsageError(f"git: {url!r} is not a repository URL", hint="fix the url (or repo) in robot.yaml")


def cache_key(url: str, version: str | None) -> str:
    """Folder name of a checkout in the cache."""
    tail = url.rstrip("/").rsplit("/", 1)[-1].removesuffix(".git") or "repo"
    safe = "".join(ch if ch.isalnum() or ch in "-_." else "-" for ch in tail)
    digest = hashlib.sha256(f"{url}@{version or ''}".encode()).hexdigest()[:12]
    return f"{safe}-{digest}"


def fetch_argv(url: str, version: str | None, *, allow_protocol: str | None = None) -> list[str]:
    """The ``git`` argv (without ``git``) that fetches ``version`` of ``url`` into the current repository.

    Raises UsageError for a URL or version git could read as anything but an operand.
    """
    check_url(url)
    if version is not None:
        check_version(version)
    return [*git_config(allow_protocol=allow_protocol), "fetch", "-q", "--depth", "1", "--end-of-options", url,
            version or "HEAD"]


def _git(args: Sequence[str], cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    if shutil.which("git") is None:
        raise ToolMissing("git is not installed", hint="apt-get install git")
    return subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True, check=False)


def fetch(url: str, version: str | None, dest: Path, *, refresh: bool = False,
          allow_protocol: str | None = None) -> str:
    """Check out ``url`` at ``version`` (branch, tag or commit; default: the remote HEAD) into ``dest``.

    Returns the commit ID. Reuses an existing checkout of the same source unless ``refresh``.
    ``allow_protocol`` is the entry's opt-in (``file`` lets git read a local repository, ``ext`` run one).
    """
    fetch_step = fetch_argv(url, version, allow_protocol=allow_protocol)
    marker = dest / ".git" / SOURCE_FILE
    source = f"{url}@{version or 'HEAD'}"
    if not refresh and marker.is_file() and marker.read_text() == source:
        head = _git(["rev-parse", "HEAD"], cwd=dest)
        if head.returncode == 0:
            return head.stdout.strip()
    remove_tree(dest)  # refused, removing nothing, when a link is on the way
    make_folder(dest)
    steps: list[list[str]] = [
        ["init", "-q"],
        fetch_step,
        ["checkout", "-q", "--force", "FETCH_HEAD", "--"],
    ]
    for step in steps:
        done = _git(step, cwd=dest)
        if done.returncode != 0:
            remove_tree(dest, ignore_errors=True)
            detail = (done.stderr or done.stdout).strip().splitlines()
            raise BuildError(
                f"git: cannot fetch {url} ({version or 'default branch'}): {detail[-1] if detail else 'failed'}",
                hint="check the URL and version in robot.yaml and that this machine can reach it",
            )
    write_atomic(marker, source)
    return _git(["rev-parse", "HEAD"], cwd=dest).stdout.strip()


def repos_file(repositories: Sequence[Repository], folder_of: dict[int, str]) -> str:
    """The repositories in vcstool's ``.repos`` YAML format (for dry runs and for users' own tools)."""
    lines = ["repositories:"]
    for index, repo in enumerate(repositories):
        lines.append(f"  {json.dumps(folder_of[index])}:")  # JSON strings are YAML scalars: one line each
        lines.append(f"    type: {repo.type}")
        lines.append(f"    url: {json.dumps(repo.url)}")
        if repo.version:
            lines.append(f"    version: {json.dumps(repo.version)}")
    return "\n".join(lines) + "\n"
