"""The export folder (``robocore export kubernetes DIR``): a folder robocore owns entirely, usually committed to the
GitOps repository, so a clone or a pull request can carry anything in it, its record of names included.

robocore writes into a new or empty folder, or one holding its record of the names it wrote
(:data:`~robocore.files.WRITTEN_RECORD`, ``.robocore-written``). Because that record travels with the repository,
it decides nothing it could not decide on its own:

- it is believed only when it is a regular file of this user that no one else may write, of at most
  :data:`MAX_RECORD_BYTES`; otherwise the export is refused in one line (the record is never followed);
- of its lines, only names export writes are read (:data:`EXPORT_NAME`: the export's own layout, no dot-part, no
  control character), so a planted ``.git/config``, ``README`` or ``ci/deploy.yaml`` is never removed;
- a file already at a name export writes is replaced only when the record lists it: a user's file is never replaced;
- a file with more than one link (a hard link to a file elsewhere) is replaced by a rename, never changed in place.

Every check runs before anything is written (:func:`check_folder`, which a dry run runs too), and an OS error on the
way (a name too long, a folder under ``/proc``) is one line naming the folder.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import stat
from collections.abc import Mapping
from pathlib import Path

from robocore.errors import UnsafePath
from robocore.export_writes import write_files
from robocore.files import PRIVATE, WRITTEN_RECORD, check_no_links, is_private, make_folder, write_atomic

#: Largest record believed: an export of 10,000 robots lists about 50,000 names (3 MB); a bigger record is not one
#: an export wrote, and reading it must stay bounded.
MAX_RECORD_BYTES = 16_000_000
#: The longest name of one part of a path, and of a whole path, Linux takes (bytes).
NAME_MAX, PATH_MAX = 255, 4095
_PART = r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,254}"
_STEM = r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,250}"
#: A name an export writes, in the export's own layout (:mod:`robocore.plan.kubernetes`): ``kustomization.yaml``,
#: ``fleet.yaml`` and ``argocd/applicationset.yaml`` at the top, a robot's overlay files in ``robots/<robot>/``, a
#: model's base in ``bases/<model>/`` (its ``.yaml`` files, ``dds/*.xml``, the health gate's ``health/*.py``); each
#: part letters, digits, ``_``, ``.`` and ``-``, none starting with ``.`` (never ``.git``). A user's file anywhere
#: else in the folder (``README``, ``ci/deploy.yaml``, ``setup.py``) is never a name a record can make an export remove.
EXPORT_NAME = re.compile(rf"(?:kustomization|fleet)\.yaml|argocd/applicationset\.yaml|robots/{_PART}/{_STEM}\.yaml"
                         rf"|bases/{_PART}/(?:{_STEM}\.yaml|dds/{_STEM}\.xml|health/{_STEM}\.py)")


def path_text(path: Path | str) -> str:
    """``path`` for a message: as it is when printable, else with its control characters escaped (a newline in a
    folder's name must not start a forged line)."""
    text = str(path)
    return text if text.isprintable() else repr(text)[1:-1]


def record_names(text: bytes) -> list[str]:
    """The names of a record's ``text`` that export writes (:data:`EXPORT_NAME`); every other line is ignored."""
    return [line for line in text.decode("utf-8", errors="replace").split("\n") if EXPORT_NAME.fullmatch(line)]


def _refuse(folder: Path, why: str, hint: str = "give a new or empty folder") -> UnsafePath:
    return UnsafePath(f"{path_text(folder)}: {why}", hint=hint)


def _read_record(folder: Path) -> bytes | None:
    """The record's bytes (None when there is none); refused when it cannot be believed."""
    record = folder / WRITTEN_RECORD
    try:
        fd = os.open(record, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_NOCTTY)
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise _refuse(folder, f"{WRITTEN_RECORD} cannot be read ({exc.strerror or exc}; a link?); robocore believes "
                      "only its own record") from None
    info = os.fstat(fd)
    why = None
    if not stat.S_ISREG(info.st_mode):
        why = "is not a regular file"
    elif not is_private(info):
        why = (f"belongs to another user (uid {info.st_uid})" if info.st_uid != os.geteuid() else
               f"may be written by group or others (mode {stat.S_IMODE(info.st_mode):04o})")
    elif info.st_size > MAX_RECORD_BYTES:
        why = f"is larger than {MAX_RECORD_BYTES:,} bytes"
    if why is not None:
        os.close(fd)
        raise _refuse(folder, f"{WRITTEN_RECORD} {why}: not believed (it decides what an export removes)",
                      hint=f"check the folder, then remove {WRITTEN_RECORD} or give a new folder")
    with os.fdopen(fd, "rb") as handle:
        data = handle.read(MAX_RECORD_BYTES + 1)
    if len(data) > MAX_RECORD_BYTES:
        raise _refuse(folder, f"{WRITTEN_RECORD} is larger than {MAX_RECORD_BYTES:,} bytes: not believed")
    return data


def check_folder(folder: Path, files: Mapping[str, object]) -> list[str]:
    """Check that ``files`` (relative path -> content) may be written into ``folder`` and return the names its
    record lists; :class:`~robocore.errors.UnsafePath` in one line otherwise (see the module). Reads only."""
    try:
        return _check_folder(folder, files)
    except OSError as exc:
        raise _refuse(folder, f"cannot be used as the export folder: {exc.strerror or exc}",
                      hint="give a folder on a writable file system, with a shorter path") from None


def _check_folder(folder: Path, files: Mapping[str, object]) -> list[str]:
    if any(len(os.fsencode(part)) > NAME_MAX for part in folder.parts) or len(os.fsencode(folder)) > PATH_MAX:
        raise OSError(errno.ENAMETOOLONG, os.strerror(errno.ENAMETOOLONG))
    try:
        info = os.lstat(folder)
    except FileNotFoundError:
        _check_creatable(folder)
        return []
    if stat.S_ISLNK(info.st_mode):
        raise _refuse(folder, "a symlink; robocore does not write through links",
                      hint=f"give the folder the link points to, or remove {path_text(folder)}")
    if not stat.S_ISDIR(info.st_mode):
        raise _refuse(folder, "is not a folder")
    own = _read_record(folder)
    if own is None:
        if any(os.scandir(folder)):
            raise _refuse(folder, f"holds files robocore did not write (no {WRITTEN_RECORD} record in it); robocore "
                          "writes only into a new or empty folder, or one it wrote before",
                          hint="give a new folder, or empty this one")
        return []
    before = record_names(own)
    listed = set(before)
    _check_parents(folder, {name.rpartition("/")[0] for name in files} - {""})
    root = str(folder)
    for name in files:
        try:
            info = os.lstat(os.path.join(root, name))
        except (FileNotFoundError, NotADirectoryError):
            continue
        if stat.S_ISLNK(info.st_mode):
            check_no_links(folder / name, anchor=folder)  # refuses it, in the words of every link refusal
        if name not in listed:
            raise _refuse(folder, f"{path_text(name)} is a file robocore did not write (its {WRITTEN_RECORD} does "
                          "not list it); robocore replaces only its own files",
                          hint=f"move {path_text(folder / name)} away, or give a new folder")
        if not stat.S_ISREG(info.st_mode):  # a folder or a FIFO where export writes a file: refused before writing
            raise _refuse(folder, f"{path_text(name)} is not a regular file; robocore writes its own file there",
                          hint=f"remove {path_text(folder / name)}")
    return before


def _check_parents(folder: Path, parents: set[str]) -> None:
    """:func:`~robocore.files.check_no_links` of each folder of ``parents`` (relative to ``folder``), each part looked
    at once (``robots`` is on the way to every robot's folder): a link, or a part on the way that is not a folder,
    is refused in check_no_links's own words."""
    modes: dict[str, int | None] = {}
    root = str(folder)
    for parent in parents:
        parts = parent.split("/")
        for index in range(len(parts)):
            key = "/".join(parts[:index + 1])
            if key not in modes:
                try:
                    modes[key] = os.lstat(os.path.join(root, key)).st_mode
                except FileNotFoundError:
                    modes[key] = None
                except OSError:
                    modes[key] = stat.S_IFLNK  # not to be read: check_no_links says why
            mode = modes[key]
            if mode is None:
                break
            if stat.S_ISLNK(mode) or (index < len(parts) - 1 and not stat.S_ISDIR(mode)):
                check_no_links(folder / parent, anchor=folder)
                break


def _check_creatable(folder: Path) -> None:
    """A folder that does not exist yet can be made: its nearest existing ancestor is a writable folder, and not
    of the kernel's own file systems (``/proc``, ``/sys``), where nothing can be made."""
    ancestor = folder.absolute().parent
    while not os.path.lexists(ancestor):
        ancestor = ancestor.parent
    real = Path(os.path.realpath(ancestor))
    if not real.is_dir() or not os.access(real, os.W_OK) or real.parts[1:2] in (("proc",), ("sys",)):
        raise OSError(errno.EACCES, f"{path_text(ancestor)} is not a folder robocore can create one in")


def write_tree(folder: Path, files: Mapping[str, str | bytes], *, mode: int | None = None,
               checked: list[str] | None = None) -> list[Path]:
    """Write ``files`` (relative path -> content) under ``folder`` after :func:`check_folder` (``checked``: what it
    returned to the caller just before, for the same files): the record first with old and new names (an
    interrupted run still owns all it wrote), then each file (:func:`~robocore.export_writes.write_files`; not
    fsynced one by one: an export is thousands of them, and each is compared with what it should hold when the
    command runs again), then the names no longer wanted are removed (regular files only, never through a link) with
    the folders they leave empty, and the record is written with the new names."""
    try:
        return _write_tree(folder, files, mode, checked)
    except OSError as exc:
        raise _refuse(folder, f"cannot be written: {exc.strerror or exc}",
                      hint="give a folder on a writable file system, with a shorter path") from None


def _write_tree(folder: Path, files: Mapping[str, str | bytes], mode: int | None,
                checked: list[str] | None) -> list[Path]:
    before = check_folder(folder, files) if checked is None else checked
    make_folder(folder, private=mode == PRIVATE)
    record = folder / WRITTEN_RECORD
    write_atomic(record, "".join(f"{n}\n" for n in sorted(set(before) | set(files))), mode=PRIVATE)
    write_files(folder, files, mode)
    _remove_stale(folder, sorted(set(before) - set(files)))
    write_atomic(record, "".join(f"{n}\n" for n in sorted(files)), mode=PRIVATE)
    return [folder / name for name in files]


def _remove_stale(folder: Path, names: list[str]) -> None:
    """Remove the regular files at ``names`` (missing ones and anything else are left alone), then the folders they
    leave empty, deepest first, each tried once. The folder is listed once (links not followed) and only the names
    found in it are looked at: a record of 100,000 names export never wrote costs its reading, not 100,000 stats."""
    if not names:
        return
    present = {os.path.relpath(os.path.join(here, name), folder)
               for here, _, found in os.walk(folder) for name in found}
    emptied: set[Path] = set()
    for name in (name for name in names if name in present):
        path = folder / name
        try:
            if not stat.S_ISREG(os.lstat(path).st_mode):
                continue
            check_no_links(path, anchor=folder)
        except (OSError, UnsafePath):  # missing, or under a link or a file: left alone
            continue
        path.unlink()
        emptied.update(parent for parent in path.parents if parent != folder and parent.is_relative_to(folder))
    for parent in sorted(emptied, key=lambda p: len(p.parts), reverse=True):
        with contextlib.suppress(OSError):  # not empty: another file of it is still wanted
            os.rmdir(parent)
