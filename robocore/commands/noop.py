"""The no-op memo: ``validate``, ``stage`` and ``build`` on an unchanged project answer in one stat pass.

A run of one of these tasks that changed nothing it depends on (the project's files, robocore's
own code, the robocore-built images of the local Docker daemon) and succeeded is recorded in
``.robocore/noop/`` with what it printed. The next identical command line first takes a fresh
snapshot of the same things; when it equals the recorded one, the recorded output is printed and
the command ends, without loading the configuration (pydantic), docker-py or rich: the task
would have found nothing to do and printed exactly that. Any difference takes the ordinary path,
which records again when it finds nothing to do.

The snapshot is stat-based and errs towards the ordinary path. Every file and folder of the
project is listed (following symlinked folders, so a change inside one is seen; only
``.git`` and these memos left out: robocore's own records in ``.robocore`` count, so a removed
install tree or build record is seen) with its type, mode, size, inode, modification and change times (a folder
by its entries), and each symlink's target; a touched file whose content is identical differs, so the ordinary path
runs, hashes its content, finds nothing to do and records the new snapshot. A file modified less
than :data:`RACY_SECONDS` before the run is not trusted (a second edit within the clock's
granularity could keep its times), so no memo is written then. Only plain command lines are
memoised (the task name, ``--quiet`` and ``--component``), on a local unix-socket daemon.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import stat
import sys
import time
from collections.abc import Collection, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TextIO

#: Tasks whose no-op is memoised, and whether their result depends on the local images.
TASKS = {"validate": False, "stage": True, "build": True}
#: Flags a memoised command line may carry (a flag that takes a value is followed by it).
PLAIN_FLAGS = {"--quiet": False, "-q": False, "--component": True, "-c": True}
#: Project folders left out of the snapshot: these memos, and git's own.
SKIPPED = (".robocore/noop", ".git")
#: A file modified this recently is not trusted to show its next change in its times.
RACY_SECONDS = 2.0
#: The environment that can change what a task does or prints.
ENVIRONMENT = ("DOCKER_HOST", "DOCKER_CONTEXT", "DOCKER_CONFIG", "NO_COLOR", "FORCE_COLOR", "TERM", "COLUMNS",
               "LINES", "HOME", "PATH", "SSH_AUTH_SOCK")
#: The label every image robocore builds carries.
IMAGES_LABEL = "dev.robocore.inputs"
#: Disables the memo when set (to any value).
DISABLE = "ROBOCORE_NO_MEMO"


class Snapshot:
    """What a task's result depends on, as a digest, and the newest modification time seen.

    (Plain classes here: importing dataclasses costs more than this whole module's work.)"""

    def __init__(self, digest: str, newest: float) -> None:
        self.digest = digest
        self.newest = newest


def _stat_row(rel: str, st: os.stat_result, link: str | None) -> str:
    if stat.S_ISDIR(st.st_mode):  # a folder's own times and size only repeat what the rows of its entries say
        return f"{rel}\0{st.st_mode}\0{st.st_ino}\0{st.st_dev}\0{link or ''}\n"
    return (f"{rel}\0{st.st_mode}\0{st.st_size}\0{st.st_ino}\0{st.st_dev}\0{st.st_mtime_ns}\0"
            f"{st.st_ctime_ns}\0{link or ''}\n")


def tree_rows(root: Path, skipped: Sequence[str] = ()) -> Iterator[tuple[str, os.stat_result]]:
    """``(relative path, lstat)`` of every entry under ``root``, following symlinked folders (each folder once);
    ``skipped`` folders (relative paths) and Python's ``__pycache__`` folders are left out."""
    seen: set[tuple[int, int]] = set()
    for here, dirs, files in os.walk(root, followlinks=True):
        base = Path(here)
        key = os.stat(here)
        if (key.st_dev, key.st_ino) in seen:
            dirs[:] = []
            continue
        seen.add((key.st_dev, key.st_ino))
        dirs[:] = sorted(d for d in dirs
                         if d != "__pycache__" and (base / d).relative_to(root).as_posix() not in skipped)
        for name in [*dirs, *sorted(files)]:
            path = base / name
            rel = path.relative_to(root).as_posix()
            yield rel, os.lstat(path)


def _tree_digest(root: Path, skipped: Sequence[str], into: hashlib._Hash) -> float:
    newest = 0.0
    into.update(_stat_row(".", os.stat(root), None).encode())
    for rel, lst in tree_rows(root, skipped):
        link = None
        st = lst
        if stat.S_ISLNK(lst.st_mode):
            link = os.readlink(root / rel)
            try:
                st = os.stat(root / rel)
            except OSError:
                link += "\0broken"
            into.update(_stat_row(rel + "\0lstat", lst, link).encode())
        into.update(_stat_row(rel, st, link).encode())
        if not stat.S_ISDIR(st.st_mode):
            newest = max(newest, st.st_mtime, st.st_ctime)
    return newest


def folders_digest(folders: Sequence[Path]) -> str:
    """A digest of every entry of ``folders`` (as the memo's snapshot lists them; a missing folder counts as
    missing): any save, even of identical content, changes it. The dev loop watches with it."""
    digest = hashlib.sha256()
    for folder in folders:
        digest.update(f"{folder}\0".encode())
        try:
            _tree_digest(folder, SKIPPED, digest)
        except OSError:
            digest.update(b"\0missing")
    return digest.hexdigest()


def snapshot(project: Path, *, images: bool, environ: dict[str, str] | None = None) -> Snapshot | None:
    """The snapshot of ``project``, robocore's code and (with ``images``) the local robocore-built images;
    None when the images cannot be asked for (the ordinary path then runs)."""
    env = dict(os.environ if environ is None else environ)
    digest = hashlib.sha256()
    digest.update(json.dumps([sys.executable, sys.version, [env.get(k) for k in ENVIRONMENT],
                              sys.stdout.isatty(), sys.stderr.isatty()]).encode())
    newest = _tree_digest(project, SKIPPED, digest)
    _tree_digest(Path(__file__).resolve().parents[1], (), digest)
    if images:
        from robocore.adapters import docker_socket

        found = docker_socket.images_digest(IMAGES_LABEL, environ=env)
        if found is None:
            return None
        digest.update(found.encode())
    return Snapshot(digest=digest.hexdigest(), newest=newest)


def command(args: Sequence[str], cwd: Path, tasks: Collection[str] = tuple(TASKS),
            flags: Mapping[str, bool] = PLAIN_FLAGS) -> tuple[Path, str, list[str]] | None:
    """``(project folder, task, the task's arguments)`` of a memoisable command line (one of ``tasks``, with only
    ``flags``: each says whether it takes a value), else None."""
    rest = list(args)
    project = cwd
    if rest[:1] in (["-p"], ["--project"]) and len(rest) >= 3:
        project, rest = Path(rest[1]), rest[2:]
    elif rest and rest[0].startswith("--project="):
        project, rest = Path(rest[0].split("=", 1)[1]), rest[1:]
    elif len(rest) >= 2 and rest[0] not in tasks and rest[1] in tasks:
        project, rest = Path(rest[0]), rest[1:]
    if not rest or rest[0] not in tasks:
        return None
    task, given = rest[0], rest[1:]
    i = 0
    while i < len(given):
        flag = given[i]
        if flag.startswith("--") and "=" in flag and flags.get(flag.split("=", 1)[0]):
            i += 1
        elif flag in flags:
            i += 2 if flags[flag] else 1
        else:
            return None
    if i != len(given):
        return None
    project = (cwd / project).absolute()
    try:
        if not (project / "robot.yaml").is_file() or (project / ".robocore").is_symlink():
            return None
    except (OSError, ValueError):  # a name too long, a NUL: the ordinary path says what is wrong
        return None
    return project, task, given


class Memo:
    """The memo of one command line in one project."""

    def __init__(self, project: Path, task: str, flags: list[str], line: Sequence[str] = ()) -> None:
        self.project = project
        self.task = task
        self.flags = flags
        self.line = list(line) or [task, *flags]  # the whole command line and folder: the output may echo them
        self.before: Snapshot | None = None
        self.started = time.time()

    @property
    def path(self) -> Path:
        """``.robocore/noop/<task>-<hash of the command line>.json``."""
        key = hashlib.sha256("\0".join(self.line).encode()).hexdigest()[:16]
        return self.project / ".robocore" / "noop" / f"{self.task}-{key}.json"

    def take(self) -> Snapshot | None:
        """A snapshot of what this task depends on; None when one cannot be taken (a file vanished or is
        unreadable while listed: the ordinary path then runs, and reports what it finds)."""
        try:
            return snapshot(self.project, images=TASKS.get(self.task, False))
        except (OSError, ValueError):
            return None

    def begin(self) -> None:
        """Take the snapshot before the ordinary run (its "before"), which :meth:`keep` compares with the one after."""
        self.before = self.take()

    def current(self) -> dict[str, object] | None:
        """The recorded document when nothing changed since it was recorded, else None; either way the snapshot
        taken is kept (the ordinary run's "before")."""
        try:
            text = self.path.read_text(encoding="utf-8")
        except OSError:
            text = None
        self.begin()
        try:
            recorded = json.loads(text) if text is not None else None
        except ValueError:
            return None
        if self.before is None or not isinstance(recorded, dict) or recorded.get("snapshot") != self.before.digest:
            return None
        return recorded

    def replay(self, out: TextIO, err: TextIO) -> bool:
        """Print the recorded output and return True when nothing changed since it was recorded; otherwise
        keep the snapshot taken (the ordinary run's "before") and return False."""
        recorded = self.current()
        if recorded is None:
            return False
        out.write(str(recorded.get("stdout", "")))
        err.write(str(recorded.get("stderr", "")))
        return True

    def record(self, stdout: str, stderr: str) -> bool:
        """After a successful ordinary run: write the memo when the run changed nothing (the snapshot after
        equals the one before) and no file is too recent to trust. True when written."""
        return self.keep({"stdout": stdout, "stderr": stderr})

    def keep(self, content: dict[str, object]) -> bool:
        """:meth:`record` with any JSON ``content``: written beside the snapshot under the same conditions."""
        after = self.take()
        if self.before is None or after is None or after.digest != self.before.digest:
            return False
        if after.newest > self.started - RACY_SECONDS:
            return False
        from robocore.files import write_atomic

        document = {"snapshot": after.digest, **content}
        write_atomic(self.path, json.dumps(document))
        return True


def for_command(args: Sequence[str], environ: Mapping[str, str] | None = None, *,
                tasks: Collection[str] = tuple(TASKS), flags: Mapping[str, bool] = PLAIN_FLAGS) -> Memo | None:
    """The memo of this command line, or None when it is not memoisable (``tasks`` and ``flags`` as
    :func:`command` takes them) or the memo is disabled."""
    env = os.environ if environ is None else environ
    if env.get(DISABLE):
        return None
    cwd = Path.cwd()
    found = command(args, cwd, tasks, flags)
    return Memo(*found, line=[str(cwd), *args]) if found is not None else None


class _Tee(io.TextIOBase):
    """Writes go to the real stream and are kept."""

    def __init__(self, real: TextIO) -> None:
        self.real = real
        self.kept = io.StringIO()

    def write(self, text: str) -> int:
        self.kept.write(text)
        return self.real.write(text)

    def flush(self) -> None:
        self.real.flush()

    def isatty(self) -> bool:
        return self.real.isatty()

    def fileno(self) -> int:
        return self.real.fileno()

    @property
    def encoding(self) -> str:  # type: ignore[override]
        return self.real.encoding


@contextmanager
def captured() -> Iterator[tuple[_Tee, _Tee]]:
    """``sys.stdout`` and ``sys.stderr`` still print, and keep what was printed."""
    out, err = _Tee(sys.stdout), _Tee(sys.stderr)
    sys.stdout, sys.stderr = out, err
    try:
        yield out, err
    finally:
        sys.stdout, sys.stderr = out.real, err.real
