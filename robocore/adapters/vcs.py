"""Git checkouts fetched on the dev machine (repositories and common packages), vcstool's .repos format.

A checkout is cached under ``.robocore/cache/git/<key>`` and reused as long as its URL and
version are unchanged; ``refresh=True`` fetches again (moving branches).
"""

from __future__ import annotations

import hashlib
import shutil
import subprocess
from collections.abc import Sequence
from pathlib import Path

from robocore.config.model import Repository
from robocore.errors import BuildError, ToolMissing

SOURCE_FILE = "robocore-source"


def cache_key(url: str, version: str | None) -> str:
    """Folder name of a checkout in the cache."""
    tail = url.rstrip("/").rsplit("/", 1)[-1].removesuffix(".git") or "repo"
    safe = "".join(ch if ch.isalnum() or ch in "-_." else "-" for ch in tail)
    digest = hashlib.sha256(f"{url}@{version or ''}".encode()).hexdigest()[:12]
    return f"{safe}-{digest}"


def _git(args: Sequence[str], cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    if shutil.which("git") is None:
        raise ToolMissing("git is not installed", hint="apt-get install git")
    return subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True, check=False)


def fetch(url: str, version: str | None, dest: Path, *, refresh: bool = False) -> str:
    """Check out ``url`` at ``version`` (branch, tag or commit; default: the remote HEAD) into ``dest``.

    Returns the commit ID. Reuses an existing checkout of the same source unless ``refresh``.
    """
    marker = dest / ".git" / SOURCE_FILE
    source = f"{url}@{version or 'HEAD'}"
    if not refresh and marker.is_file() and marker.read_text() == source:
        head = _git(["rev-parse", "HEAD"], cwd=dest)
        if head.returncode == 0:
            return head.stdout.strip()
    if dest.exists():
        shutil.rmtree(dest)
    dest.mkdir(parents=True)
    steps: list[list[str]] = [
        ["init", "-q"],
        ["fetch", "-q", "--depth", "1", url, version or "HEAD"],
        ["checkout", "-q", "--force", "FETCH_HEAD"],
    ]
    for step in steps:
        done = _git(step, cwd=dest)
        if done.returncode != 0:
            shutil.rmtree(dest, ignore_errors=True)
            detail = (done.stderr or done.stdout).strip().splitlines()
            raise BuildError(
                f"git: cannot fetch {url} ({version or 'default branch'}): {detail[-1] if detail else 'failed'}",
                hint="check the URL and version in robot.yaml and that this machine can reach it",
            )
    marker.write_text(source)
    return _git(["rev-parse", "HEAD"], cwd=dest).stdout.strip()


def repos_file(repositories: Sequence[Repository], folder_of: dict[int, str]) -> str:
    """The repositories in vcstool's ``.repos`` YAML format (for dry runs and for users' own tools)."""
    lines = ["repositories:"]
    for index, repo in enumerate(repositories):
        lines.append(f"  {folder_of[index]}:")
        lines.append(f"    type: {repo.type}")
        lines.append(f"    url: {repo.url}")
        if repo.version:
            lines.append(f"    version: {repo.version}")
    return "\n".join(lines) + "\n"
