"""The no-op memo: ``validate``, ``stage`` and ``build`` on an unchanged project answer in one stat pass.

A run of one of these tasks that changed nothing it depends on (the project's files, robocore's
own code, the robocore-built images of the local Docker daemon) and succeeded is recorded in
``.robocore/noop/`` with what it printed. The next identical command line first takes a fresh
snapshot of the same things; when it equals the recorded one, the recorded output is printed and
the command ends, without loading the configuration (pydantic), docker-py or rich: the task
would have found nothing to do and printed exactly that. Any difference takes the ordinary path,
which records again when it finds nothing to do.

The snapshot is stat-based and errs towards the ordinary path. Every file and folder of the
project is listed (following symlinked folders that stay inside the project, so a change inside one is seen;
only ``.git`` and these memos left out: robocore's own records in ``.robocore`` count, so a removed
install tree or build record is seen) with its type, mode, size, inode, modification and change times (a folder
by its entries), and each symlink's target; a touched file whose content is identical differs, so the ordinary path
runs, hashes its content, finds nothing to do and records the new snapshot. The walk never leaves the project:
a symlink to a folder outside it makes the project unmemoisable (the ordinary path runs, and refuses the link
or, where robot.yaml allows it, reads through it).

A file changed less than :data:`RACY_SECONDS` before the run is "racily clean" (git's term): a second edit within
the file system's time granularity could keep every time the snapshot holds. Such files are hashed, the memo
keeps their hashes, and every replay hashes them again, so a memo is written and answers at any file age and a
second edit within one tick is still seen.

A memo file is believed only when it can be trusted: reached without a link, a regular file of this user that no
one else may write (in folders likewise), at most :data:`MAX_MEMO_BYTES`, its checksum matching, its snapshot
(which names the project's path and every file's inode and change time) equal to a fresh one. Anything else is
dropped. Only plain command lines are memoised (the task name, ``--quiet`` and ``--component``), on a local
unix-socket daemon.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import sys
import time
from collections.abc import Collection, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path

from robocore.commands.support.trees import MAX_YOUNG_BYTES, Snapshot, Untrusted, hash_file, inside, tree_digest

TYPE_CHECKING = False  # typing's constant, without importing typing on the memo's path (12M instructions)
if TYPE_CHECKING:
    from typing import TextIO

#: Tasks whose no-op is memoised, and whether their result depends on the local images.
TASKS = {"validate": False, "stage": True, "build": True}
#: Flags a memoised command line may carry (a flag that takes a value is followed by it).
PLAIN_FLAGS = {"--quiet": False, "-q": False, "--component": True, "-c": True}
#: Project folders left out of the snapshot: these memos, and git's own.
SKIPPED = (".robocore/noop", ".git")
#: A file changed this recently is not trusted to show its next change in its times (the coarsest file system
#: clock, FAT's, ticks every 2 s): its content is hashed into the memo.
RACY_SECONDS = 2.0
#: A memo file larger than this is neither read nor written (a recorded output that long is not worth replaying).
MAX_MEMO_BYTES = 8 << 20
#: The environment that can change what a task does or prints.
ENVIRONMENT = ("DOCKER_HOST", "DOCKER_CONTEXT", "DOCKER_CONFIG", "NO_COLOR", "FORCE_COLOR", "TERM", "COLUMNS",
               "LINES", "HOME", "PATH", "SSH_AUTH_SOCK")
#: The label every image robocore builds carries.
IMAGES_LABEL = "dev.robocore.inputs"
#: Disables the memo when set (to any value).
DISABLE = "ROBOCORE_NO_MEMO"


def folders_digest(folders: Sequence[Path], boundary: Path) -> str:
    """A digest of every entry of ``folders`` (as the memo's snapshot lists them; a missing folder counts as
    missing): any save, even of identical content, changes it. The dev loop watches with it. Symlinked folders
    inside ``boundary`` (the project) are followed; a link leading outside counts by its own row only, never
    followed, so nothing outside the project is read or watched through a link."""
    digest = hashlib.sha256()
    for folder in folders:
        digest.update(f"{folder}\0".encode())
        try:
            tree_digest(folder, SKIPPED, digest, boundary=boundary, stop_at_boundary=True)
        except OSError:
            digest.update(b"\0missing")
    return digest.hexdigest()


def _code_root() -> Path:
    return Path(__file__).resolve().parents[2]  # robocore/ (this file is robocore/commands/support/noop.py)


def snapshot(project: Path, *, images: bool, environ: dict[str, str] | None = None,
             young_after: float | None = None) -> Snapshot | None:
    """The snapshot of ``project``, robocore's code and (with ``images``) the local robocore-built images;
    None when the images cannot be asked for (the ordinary path then runs). Files changed at or after
    ``young_after`` (default: :data:`RACY_SECONDS` ago) are hashed into :attr:`Snapshot.young`. Raises
    :class:`Untrusted` for a project whose walk would leave it through a link."""
    env = dict(os.environ if environ is None else environ)
    threshold = time.time() - RACY_SECONDS if young_after is None else young_after
    digest = hashlib.sha256()
    digest.update(json.dumps([str(project), sys.executable, sys.version, [env.get(k) for k in ENVIRONMENT],
                              sys.stdout.isatty(), sys.stderr.isatty()]).encode())
    young: dict[str, str] = {}
    budget = [MAX_YOUNG_BYTES]
    tree_digest(project, SKIPPED, digest, boundary=project, young_after=threshold, young=young, budget=budget)
    code = _code_root()
    tree_digest(code, (), digest, boundary=code, young_after=threshold, young=young, tag=":robocore/",
                 budget=budget)
    if images:
        from robocore.adapters import docker_socket

        found = docker_socket.images_digest(IMAGES_LABEL, environ=env)
        if found is None:
            return None
        digest.update(found.encode())
    return Snapshot(digest=digest.hexdigest(), young=young)


def _young_now(project: Path, rel: str) -> str | None:
    """The content hash of a file the memo recorded as young, now (None when it cannot be read as a file)."""
    root = _code_root() if rel.startswith(":robocore/") else project
    path = root / rel.removeprefix(":robocore/")
    try:
        if not inside(os.path.realpath(path), os.path.realpath(root)):
            return None  # a memo naming a file outside (forged): nothing outside is read
        return hash_file(str(path), [MAX_YOUNG_BYTES])
    except (OSError, Untrusted):
        return None


def seal(document: Mapping[str, object]) -> str:
    """The text of a memo file: a checksum line, then ``document`` as JSON. A memo whose checksum does not match
    (edited, truncated, half-written) is dropped."""
    text = json.dumps(document, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest() + "\n" + text


def unseal(data: bytes) -> dict[str, object] | None:
    """The document of a memo file's bytes, None unless its checksum matches and it is a JSON object."""
    head, _, body = data.partition(b"\n")
    if hashlib.sha256(body).hexdigest().encode() != head:
        return None
    try:
        document = json.loads(body)
    except ValueError:
        return None
    return document if isinstance(document, dict) else None


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
        if flag.startswith("--") and "=" in flag and flags.get(flag.split("=", 1)[0]) and flag.split("=", 1)[1]:
            i += 1
        elif flag in flags and (not flags[flag] or (i + 1 < len(given) and given[i + 1])):
            i += 2 if flags[flag] else 1
        else:
            return None  # an unknown flag, or an empty value: the ordinary path says what is wrong
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
        key = hashlib.sha256("\0".join(self.line).encode(errors="surrogateescape")).hexdigest()[:16]
        return self.project / ".robocore" / "noop" / f"{self.task}-{key}.json"

    def take(self) -> Snapshot | None:
        """A snapshot of what this task depends on, files changed since :data:`RACY_SECONDS` before the command
        started hashed; None when one cannot be taken (a file vanished or is unreadable while listed, a link
        leaves the project: the ordinary path then runs, and reports what it finds)."""
        try:
            return snapshot(self.project, images=TASKS.get(self.task, False),
                            young_after=self.started - RACY_SECONDS)
        except (OSError, ValueError, Untrusted):
            return None

    def begin(self) -> None:
        """Take the snapshot before the ordinary run (its "before"), which :meth:`keep` compares with the one after."""
        self.before = self.take()

    def exists(self) -> bool:
        """Whether anything is at the memo's name (a quick look before a snapshot is worth taking)."""
        try:
            return os.path.lexists(self.path)
        except ValueError:
            return False

    def _recorded(self) -> dict[str, object] | None:
        """The memo file's document when it can be trusted: no link on the way from the project or at it, a
        regular file of this user that no one else may write, in folders of this user that no one else may write,
        at most :data:`MAX_MEMO_BYTES`, its checksum matching. Anything else there is dropped (removed as a
        name, never followed), so the next ordinary run writes a good one."""
        from robocore.errors import UnsafePath
        from robocore.files import check_no_links, is_private, read_own_file

        path = self.path
        try:
            check_no_links(path.parent, anchor=self.project)  # a link at the memo's name itself is dropped
            folders_ok = all(is_private(os.lstat(p)) for p in (path.parent.parent, path.parent))
        except FileNotFoundError:
            return None
        except (OSError, UnsafePath):
            return None  # a linked state folder: the ordinary path refuses it in one line
        data = read_own_file(path, limit=MAX_MEMO_BYTES, private=True) if folders_ok else None
        document = unseal(data) if data is not None else None
        if document is None and folders_ok:
            self.drop()
        return document

    def drop(self) -> None:
        """Remove whatever is at the memo's name (a link as a link), when its folders are robocore's own."""
        from robocore.errors import UnsafePath
        from robocore.files import remove_file

        with contextlib.suppress(OSError, UnsafePath):
            remove_file(self.path, any_kind=True)

    def current(self) -> dict[str, object] | None:
        """The recorded document when nothing changed since it was recorded, else None; either way the snapshot
        taken is kept (the ordinary run's "before"). A file the memo recorded as young (changed within
        :data:`RACY_SECONDS` of its recording) is hashed again: its times alone cannot show a second change."""
        recorded = self._recorded() if self.exists() else None
        self.begin()
        if self.before is None or recorded is None or recorded.get("snapshot") != self.before.digest:
            return None
        young = recorded.get("young")
        if not isinstance(young, dict):
            return None
        for rel, digest in young.items():
            now = self.before.young.get(rel) or _young_now(self.project, rel)
            if now is None or now != digest:
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
        equals the one before, young files' contents included). True when written."""
        return self.keep({"stdout": stdout, "stderr": stderr})

    def keep(self, content: dict[str, object]) -> bool:
        """:meth:`record` with any JSON ``content``: written beside the snapshot under the same conditions, as a
        private file (0600 in a 0700 folder) whatever the umask. Never raises for a memo that cannot be written
        (a linked folder, a full disk): the next run takes the ordinary path, which reports what it finds."""
        from robocore.errors import RobocoreError
        from robocore.files import PRIVATE, write_atomic

        after = self.take()
        before = self.before
        if before is None or after is None or after.digest != before.digest or after.young != before.young:
            return False
        text = seal({"snapshot": after.digest, "young": after.young, **content})
        if len(text.encode()) > MAX_MEMO_BYTES:
            return False
        try:
            write_atomic(self.path, text, mode=PRIVATE)
        except (OSError, RobocoreError):
            return False
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
