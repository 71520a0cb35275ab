"""Files robocore writes or copies: atomic writes with the user's umask, and symlinks that leave the project.

The umask is read once, when this module is imported (from ``/proc/self/status`` where the kernel
shows it, else by setting and restoring it): it is process-wide state, and setting it while other
threads create files would give those files the wrong mode.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Callable, Iterator
from pathlib import Path

from robocore.errors import UnsafePath

#: The file that describes a robot, at the top of its project folder.
ROBOT_FILE = "robot.yaml"


def _read_umask() -> int:
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
UMASK = _read_umask()
#: Mode of generated files that hold environment values or other data for the user's eyes only.
PRIVATE = 0o600


def default_mode() -> int:
    """The mode a new file gets here: ``0o666`` less the umask."""
    return 0o666 & ~UMASK


def write_atomic(path: Path, content: str | bytes, *, mode: int | None = None) -> bool:
    """Write ``content`` to ``path`` through a temp file and rename; return False if unchanged.

    ``mode`` None gives the mode any new file gets (``0o666`` less the umask); an explicit mode is
    applied as given (:data:`PRIVATE` for files holding environment values). An unchanged file keeps
    its content but still gets ``mode``, so a file written before with a wider mode is narrowed.
    """
    data = content.encode("utf-8") if isinstance(content, str) else content
    wanted = default_mode() if mode is None else mode
    try:
        if path.read_bytes() == data:
            if mode is not None and not path.is_symlink() and (path.stat().st_mode & 0o7777) != wanted:
                os.chmod(path, wanted)
            return False
    except OSError:
        pass
    path.parent.mkdir(parents=True, exist_ok=True)
    import tempfile  # here, not at import: the command line's first steps read paths only

    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.chmod(tmp, wanted)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return True


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
