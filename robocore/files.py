"""Files robocore writes, removes, reads or copies: atomic writes with modes that do not depend on the umask,
never through a link.

Every path robocore writes or removes in a project lies under its state folder (:data:`STATE_DIR`). Before
writing, creating or removing there, each folder from the project folder down (and the file itself) is
checked without following symlinks: a link (a cloned repository can carry one where robocore writes) is
refused with :class:`~robocore.errors.UnsafePath` naming it, before anything is written or removed.
Files robocore reads from the project (robot.yaml, package.xml, ``.repos``, TLS files) are read with
:func:`read_project_file`: inside the project after links are followed, a regular file, never a FIFO.

Under :data:`STATE_DIR` every folder robocore creates is 0700 and every file 0600, whatever the umask, except
the few that a process of another user reads (:data:`SHARED` and :data:`SHARED_DIR`); nothing robocore
creates anywhere may be written by others (:data:`NEVER`).

The umask is read once, when this module is imported (from ``/proc/self/status`` where the kernel
shows it, else by setting and restoring it): it is process-wide state, and setting it while other
threads create files would give those files the wrong mode.
"""

from __future__ import annotations

import contextlib
import os
import stat
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path

from robocore.errors import UnsafePath

#: The file that describes a robot, at the top of its project folder.
ROBOT_FILE = "robot.yaml"
#: The fleet file of a project (many robots of its robot.yaml), next to robot.yaml; optional.
FLEET_FILE = "fleet.yaml"
#: The folder of everything robocore writes in a project (generated files, builds, caches, records).
STATE_DIR = ".robocore"
#: Mode of every folder robocore creates under :data:`STATE_DIR` (whatever the umask), and of the folders
#: holding private files elsewhere (the X11 cookies).
PRIVATE_DIR = 0o700
#: Mode of the few folders under :data:`STATE_DIR` that a process of another user reads: those mounted into
#: containers, whose user may not be the invoking one (``dds``, ``shell``), and those sent to the robot hosts as
#: they are (a component's ``install`` tree, the ``sync`` folder of linked read-only volumes).
SHARED_DIR = 0o755
#: The record, in a folder of generated files, of the names robocore wrote there (what stale cleaning may remove).
WRITTEN_RECORD = ".robocore-written"


def read_umask() -> int:
    """This process's umask, read without changing it (``/proc/self/status``; elsewhere set and restored once)."""
    try:
        with open("/proc/self/status", encoding="ascii", errors="replace") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    old = os.umask(0o022)  # only here, at import, before robocore starts any thread
    os.umask(old)
    return old


#: The process's umask when robocore started.
UMASK = read_umask()
#: Mode of every file robocore writes under :data:`STATE_DIR` unless it is :data:`SHARED` (whatever the umask).
PRIVATE = 0o600
#: Mode of the files robocore writes under :data:`STATE_DIR` that a process of another user reads: the DDS
#: profiles and the dev shell's start files, read inside containers whose user may not be the invoking one.
SHARED = 0o644
#: Bits no file or folder robocore creates ever has, whatever the umask: no one else may write to them.
NEVER = 0o022
#: Largest state record robocore reads (build and sync state, run history, the warmed hosts, a folder's record of
#: names): those it writes are kilobytes, a build state of 100,000 files about 10 MB; a bigger one is not one it
#: wrote, and is read as none, in bounded time and memory.
MAX_STATE_RECORD_BYTES = 64_000_000


@contextlib.contextmanager
def creating_for_this_user() -> Iterator[None]:
    """Within: files and folders made by this process and its children (a template engine, git) are writable by no
    one else whatever the umask (:data:`NEVER` added to it). Only where no other thread creates files meanwhile."""
    old = os.umask(UMASK | NEVER)
    try:
        yield
    finally:
        os.umask(old)


def narrow_new(root: Path, before: set[Path]) -> None:
    """Remove the bits that let others write from every entry under ``root`` (``root`` included) of this user that is
    not in ``before`` (what was there already): what a tool copied with its source's modes. Links are not followed."""
    _narrow(root, before)
    for here, folders, names in os.walk(root):
        for name in [*folders, *names]:
            _narrow(Path(here) / name, before)


def _narrow(path: Path, before: set[Path]) -> None:
    info = os.lstat(path)
    if path not in before and not stat.S_ISLNK(info.st_mode) and info.st_mode & NEVER and info.st_uid == os.geteuid():
        os.chmod(path, stat.S_IMODE(info.st_mode) & ~NEVER)


def default_mode() -> int:
    """The mode a new file outside :data:`STATE_DIR` gets: ``0o666`` less the umask, never writable by others."""
    return 0o666 & ~UMASK & ~NEVER


def state_mode(path: Path, mode: int | None = None) -> int:
    """The mode of a file robocore writes at ``path``: ``mode`` when given; else :data:`PRIVATE` under
    :data:`STATE_DIR` and :func:`default_mode` elsewhere. Never writable by others."""
    if mode is not None:
        return mode & ~NEVER
    return PRIVATE if _anchor(path) is not None else default_mode()


def _anchor(path: Path) -> Path | None:
    """The project folder of ``path``: the parent of its last :data:`STATE_DIR` part; None when it has none
    (a file outside any project, such as the ssh folder in /tmp)."""
    parts = path.parts
    for index in range(len(parts) - 1, -1, -1):
        if parts[index] == STATE_DIR:
            return Path(*parts[:index])
    return None


def _unsafe_link(path: Path, anchor: Path) -> UnsafePath:
    try:
        target = os.readlink(path)
    except OSError:
        target = "?"
    shown = path.relative_to(anchor) if path.is_relative_to(anchor) else path
    return UnsafePath(f"{shown}: a symlink (to {target!r}) where robocore writes its own files; robocore does not "
                      "write or remove through links", hint=f"remove the link {path} (robocore recreates the folder)")


def check_no_links(path: Path, *, anchor: Path | None = None) -> None:
    """Raise :class:`~robocore.errors.UnsafePath` when ``path`` or a folder between the project folder and it
    is a symlink, or a folder on the way is not a folder. Checked with lstat (links are never followed); the
    project folder is the parent of the :data:`STATE_DIR` part (or ``anchor``); a path outside any project
    is not checked. Parts that do not exist yet are fine (robocore creates them)."""
    anchor = _anchor(path) if anchor is None else anchor
    if anchor is None or not path.is_relative_to(anchor):
        return
    current = anchor
    rel = path.relative_to(anchor).parts
    for index, part in enumerate(rel):
        current = current / part
        try:
            info = os.lstat(current)
        except FileNotFoundError:
            return
        except OSError as exc:
            raise UnsafePath(f"{current}: cannot be checked: {exc.strerror or exc}") from None
        if stat.S_ISLNK(info.st_mode):
            raise _unsafe_link(current, anchor)
        if index < len(rel) - 1 and not stat.S_ISDIR(info.st_mode):
            raise UnsafePath(f"{current.relative_to(anchor)}: is not a folder; robocore keeps its files below it",
                             hint=f"remove {current}")


def make_folder(path: Path, *, private: bool = False, shared: bool = False) -> Path:
    """Create ``path`` and its missing parents, refusing any symlink on the way (:func:`check_no_links`).

    Every folder created under :data:`STATE_DIR` is :data:`PRIVATE_DIR` (0700) whatever the umask, except
    ``path`` itself when ``shared`` (:data:`SHARED_DIR`, 0755: another user reads it). ``private`` makes ``path``
    0700 even when it exists already, or lies outside the state folder. A folder of this user on the way from the
    state folder to ``path`` that others may write to (made under a loose umask before) loses those bits.
    Elsewhere new folders get ``0o777`` less the umask, never writable by others."""
    check_no_links(path)
    anchor = _anchor(path)
    missing = []
    probe = path
    while not os.path.lexists(probe) and probe != probe.parent:
        missing.append(probe)
        probe = probe.parent
    for folder in reversed(missing):
        if _anchor(folder) is not None or (private and folder == path):
            wanted: int | None = SHARED_DIR if shared and folder == path else PRIVATE_DIR
        else:
            wanted = None  # outside the state folder: the umask's mode, never writable by others
        created = True
        try:
            os.mkdir(folder, 0o777 & ~NEVER if wanted is None else wanted)
        except FileExistsError:
            created = False  # another process made it meanwhile
        check_no_links(folder, anchor=anchor)  # another process may have made it a link meanwhile
        if created and wanted is not None and stat.S_IMODE(os.lstat(folder).st_mode) != wanted:
            os.chmod(folder, wanted)  # mkdir's mode passes through the umask
    if not path.is_dir():
        raise UnsafePath(f"{path}: is not a folder; robocore keeps its files in it", hint=f"remove {path}")
    if private and stat.S_IMODE(os.lstat(path).st_mode) != PRIVATE_DIR:
        os.chmod(path, PRIVATE_DIR)
    if anchor is not None:  # state folders of this user made writable by others (a loose umask before) are narrowed
        for folder in (path, *path.parents):
            if not folder.is_relative_to(anchor / STATE_DIR):
                break
            info = os.lstat(folder)
            if stat.S_IMODE(info.st_mode) & NEVER and info.st_uid == os.geteuid():
                os.chmod(folder, stat.S_IMODE(info.st_mode) & ~NEVER)
    return path


def is_private(info: os.stat_result) -> bool:
    """True when ``info`` (an lstat) is owned by this process's user and no one else may write to it: what a
    record must be for robocore to believe it (another local user could otherwise have written it)."""
    return info.st_uid == os.geteuid() and not info.st_mode & 0o022


def read_own_file(path: Path, *, limit: int | None = None, private: bool = False) -> bytes | None:
    """The content of ``path``, a file robocore wrote, when it is a regular file; None otherwise (missing, a link,
    a FIFO, a device: never followed, never blocking). For robocore's records under ``.robocore/``.

    ``limit``: None too when the file holds more than that many bytes (no more than one byte past it is read).
    ``private``: None too when the file is not :func:`is_private` (another user could have written it)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_NOCTTY)
    except (OSError, ValueError):
        return None
    info = os.fstat(fd)
    if not stat.S_ISREG(info.st_mode) or (private and not is_private(info)):
        os.close(fd)
        return None
    with os.fdopen(fd, "rb") as handle:
        if limit is None:
            return handle.read()
        data = handle.read(limit + 1)
        return None if len(data) > limit else data


def write_atomic(path: Path, content: str | bytes, *, mode: int | None = None, private_dir: bool = False,
                 durable: bool = True) -> bool:
    """Write ``content`` to ``path`` through a temp file and rename; return False if unchanged.

    ``mode`` None gives :data:`PRIVATE` under :data:`STATE_DIR` and the umask's mode elsewhere
    (:func:`state_mode`); an explicit mode is applied as given, less the bits that let others write
    (:data:`SHARED` for the files another user reads), whatever the umask. A :data:`PRIVATE` file's folder is
    made 0700 (as ``private_dir`` asks). An unchanged file keeps its content but still gets its mode, so a file
    written before with a wider mode is narrowed (one with more than one link is replaced instead, so that another
    name of it, outside, is left as it is). A symlink at ``path`` or on the way to
    it from the project folder is refused (:func:`check_no_links`) before anything is written.
    ``durable`` False skips the fsync before the rename: for files the same command writes again when they come
    out wrong after a crash (:func:`robocore.export_folder.write_tree`'s), where one fsync per file costs more than
    the writing.
    """
    data = content.encode("utf-8") if isinstance(content, str) else content
    wanted = state_mode(path, mode)
    check_no_links(path)
    make_folder(path.parent, private=private_dir or mode == PRIVATE, shared=mode == SHARED)
    if os.path.lexists(path) and not stat.S_ISREG(os.lstat(path).st_mode):
        raise UnsafePath(f"{path}: is not a regular file; robocore writes its own file there", hint=f"remove {path}")
    # a file with another link (a hard link to a file elsewhere) is replaced by the rename below, never chmodded
    if read_own_file(path) == data and os.lstat(path).st_nlink == 1:
        if (os.lstat(path).st_mode & 0o7777) != wanted:
            os.chmod(path, wanted)
        return False
    import tempfile  # here, not at import: the command line's first steps read paths only

    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            if durable:
                os.fsync(handle.fileno())
        os.chmod(tmp, wanted)
        os.replace(tmp, path)  # a rename replaces a name, never what a link there points to
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return True


def remove_file(path: Path, *, any_kind: bool = False) -> bool:
    """Remove the regular file ``path`` (False when there is none); a link at it or on the way is refused.

    ``any_kind`` removes whatever non-folder entry is at ``path`` (a link is removed as a link, never followed; a
    FIFO or device node as a name): for a record robocore drops because it cannot be trusted."""
    check_no_links(path.parent if any_kind else path)
    try:
        info = os.lstat(path)
    except FileNotFoundError:
        return False
    if any_kind and not stat.S_ISDIR(info.st_mode):
        path.unlink()
        return True
    if not stat.S_ISREG(info.st_mode):
        raise UnsafePath(f"{path}: is not a regular file; robocore removes only files it wrote", hint=f"remove {path}")
    path.unlink()
    return True


def remove_tree(path: Path, *, ignore_errors: bool = False) -> bool:
    """Remove the folder ``path`` and everything below it (False when there is none), refusing a link at it
    or on the way to it; links inside are removed as links, never followed (shutil.rmtree's fd-based walk).
    ``ignore_errors`` leaves what cannot be removed (files a container made as another user)."""
    import shutil

    check_no_links(path)
    if not os.path.lexists(path):
        return False
    shutil.rmtree(path, ignore_errors=ignore_errors)
    return True


def write_generated(folder: Path, files: Mapping[str, str | bytes], *, mode: int | None = None) -> list[Path]:
    """Write ``files`` (name -> content) into ``folder`` and remove the ones robocore wrote there before that
    are no longer wanted: only names listed in the folder's :data:`WRITTEN_RECORD`, never a file robocore did
    not write. The folder is private (0700) when ``mode`` is :data:`PRIVATE`, 0755 when :data:`SHARED`."""
    make_folder(folder, private=mode == PRIVATE, shared=mode == SHARED)
    record = folder / WRITTEN_RECORD
    before = (read_own_file(record, limit=MAX_STATE_RECORD_BYTES) or b"").decode("utf-8", errors="replace").splitlines()
    paths = []
    for name, content in files.items():
        write_atomic(folder / name, content, mode=mode)
        paths.append(folder / name)
    for stale in sorted(set(before) - set(files)):
        if stale and "/" not in stale and not stale.startswith("."):
            with contextlib.suppress(UnsafePath):  # a name now held by something else is left alone
                remove_file(folder / stale)
    write_atomic(record, "".join(f"{name}\n" for name in sorted(files)), mode=mode)
    return paths


def read_project_file(path: Path, project: Path, *, limit: int | None = None, what: str = "file") -> bytes:
    """The bytes of ``path``, a file of the project that robocore reads (robot.yaml, package.xml, ``.repos``,
    TLS files): :class:`~robocore.errors.UnsafePath` in one line, at once, when a link leads it outside
    ``project`` or it is not a regular file (a FIFO, a device, a folder), and reading never blocks. ``limit``
    reads at most that many bytes plus one (the caller refuses what is over)."""
    shown = path.relative_to(project) if path.is_relative_to(project) else path
    try:
        real = Path(os.path.realpath(path))
    except (OSError, ValueError) as exc:
        raise UnsafePath(f"{shown}: cannot be read: {getattr(exc, 'strerror', None) or exc}") from None
    if not real.is_relative_to(Path(os.path.realpath(project))):
        raise UnsafePath(f"{shown}: a symlink to {str(real)!r}, outside the project folder; robocore reads its "
                         f"{what} only from inside the project", hint="copy the file into the project")
    try:
        fd = os.open(real, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | os.O_NOFOLLOW)
    except OSError as exc:
        raise UnsafePath(f"{shown}: cannot be read: {exc.strerror or exc}") from None
    with os.fdopen(fd, "rb") as handle:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise UnsafePath(f"{shown}: is not a regular file (a FIFO, device or folder); robocore reads its {what} "
                             "only from a regular file")
        return handle.read() if limit is None else handle.read(limit + 1)


def is_inside(path: Path, folder: Path) -> bool:
    """True when ``path`` (resolved, symlinks followed) is ``folder`` (resolved) or below it."""
    return path.resolve().is_relative_to(folder.resolve())


def links_leaving(root: Path, boundary: Path, *,
                  skip: Callable[[Path, str], bool] | None = None) -> Iterator[tuple[Path, str]]:
    """Every symlink at or under ``root`` whose target, followed to the end, is not inside ``boundary``,
    with its target as written. Folders behind symlinks are not walked (the link itself is reported
    if it leaves), nor folders for which ``skip(parent, name)`` is true (what is never copied)."""
    boundary = boundary.resolve()
    if root.is_symlink() and not is_inside(root, boundary):
        yield root, os.readlink(root)
        return
    for dirpath, dirnames, filenames in os.walk(root):
        here = Path(dirpath)
        if skip is not None:
            dirnames[:] = [d for d in dirnames if not skip(here, d)]
        for name in sorted([*dirnames, *filenames]):
            path = here / name
            if path.is_symlink() and not is_inside(path, boundary):
                yield path, os.readlink(path)


def refuse_links_leaving(root: Path, boundary: Path, *, what: str, allowed: bool = False,
                         skip: Callable[[Path, str], bool] | None = None) -> None:
    """Raise :class:`~robocore.errors.UnsafePath` naming the first symlink at or under ``root`` that leads
    out of ``boundary`` (the project), unless ``allowed`` (robot.yaml opts in). ``what`` says what the
    files are for (``"the workspace of component talker"``); ``skip`` as for :func:`links_leaving`."""
    if allowed:
        return
    for path, target in links_leaving(root, boundary, skip=skip):
        boundary = boundary.resolve()
        shown = path.relative_to(boundary) if path.is_relative_to(boundary) else path
        raise UnsafePath(f"{shown}: a symlink to {target!r}, outside the project folder; robocore does not copy "
                         f"files from outside the project ({what})",
                         hint="copy what it points to into the project, or remove the link")


def path_kind(path: Path) -> tuple[str, str]:
    """What ``path`` is: ``dir``, ``file``, ``missing`` or ``unusable`` (a name too long, a symlink loop, no
    permission: the reason comes second). Never raises, whatever robot.yaml names."""
    try:
        mode = path.stat().st_mode
    except (FileNotFoundError, NotADirectoryError):
        return "missing", ""
    except (OSError, ValueError) as error:  # ValueError: a NUL byte in the name
        return "unusable", getattr(error, "strerror", None) or str(error)
    return ("dir" if stat.S_ISDIR(mode) else "file"), ""
