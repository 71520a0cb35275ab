"""Writing the files of the export folder (``robocore export kubernetes DIR``), tens of thousands at a time.

:func:`write_files` gives every file what :func:`robocore.files.write_atomic` gives it (its mode whatever the umask,
nothing written through a link, an unchanged file left as it is, a file with another link replaced, never changed
in place), at a fraction of its cost: an export of 10,000 robots is 20,000 files (bench/fleet_scale.py), and
``write_atomic`` looks every path up again from the root, part by part, and writes each file as a temporary file
renamed over it. Here:

- each folder is opened once, part by part from the export folder, each part without following a link
  (``O_NOFOLLOW``); a part that is a link or not a folder is refused in :func:`robocore.files.check_no_links`'s
  words; a missing folder is made by :func:`robocore.files.make_folder` (its modes);
- a name not there yet is created in its folder's descriptor with ``O_EXCL`` (nothing may be at it, not even a
  link) and written: an open, a write and a close. Not fsynced, and a file interrupted while written is one the
  record lists: the next export finds it different and replaces it (:mod:`robocore.export_folder`);
- a name already there is refused unless it is a regular file, kept when it holds the content and has no other
  link (its mode set), else replaced by the rename of a new temporary file.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
from collections.abc import Mapping
from pathlib import Path

from robocore.errors import UnsafePath
from robocore.files import PRIVATE, PRIVATE_DIR, STATE_DIR, check_no_links, make_folder, read_umask, state_mode

_FOLDER = os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC
_CREATE = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC
_READ = os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_NOCTTY | os.O_CLOEXEC


def write_files(folder: Path, files: Mapping[str, str | bytes], mode: int | None) -> None:
    """Write ``files`` (path relative to ``folder`` -> content) under ``folder``, an existing folder, with the mode
    :func:`~robocore.files.write_atomic` gives for ``mode``; folders missing on the way are made as
    :func:`~robocore.files.make_folder` makes them (``private`` when ``mode`` is :data:`~robocore.files.PRIVATE`)."""
    by_folder: dict[str, list[tuple[str, str | bytes]]] = {}
    for name, content in files.items():
        parent, _, base = name.rpartition("/")
        by_folder.setdefault(parent, []).append((base, content))
    opened = _Folders(folder, private=mode == PRIVATE)
    umask = read_umask()  # now: what the kernel takes from a new file's mode
    try:
        for parent, entries in by_folder.items():
            where = folder / parent if parent else folder
            folder_fd = opened.open(parent)
            try:
                for base, content in entries:
                    data = content.encode("utf-8") if isinstance(content, str) else content
                    wanted = state_mode(where / base, mode)
                    try:
                        fd = os.open(base, _CREATE, wanted, dir_fd=folder_fd)
                    except FileExistsError:
                        _rewrite(folder_fd, where / base, data, wanted)
                        continue
                    _fill(fd, data, folder_fd, base, wanted if wanted & umask else None)
            finally:
                if parent:
                    os.close(folder_fd)
    finally:
        opened.close()


class _Folders:
    """Descriptors of the folders under ``root``, each opened from its parent's without following a link; the
    folders that hold other folders are kept open (a handful: ``robots``, ``bases``, ``bases/<model>``)."""

    def __init__(self, root: Path, *, private: bool) -> None:
        self.root, self.private = root, private
        #: Under a state folder make_folder also narrows folders others may write: it looks at each folder then.
        self.in_state = STATE_DIR in root.absolute().parts
        self.root_fd = os.open(root, _FOLDER)
        self.kept: dict[str, int] = {}

    def open(self, parent: str, *, made: bool = False) -> int:
        """A new descriptor of ``root/parent`` (the root's own for ``""``), the folder made when it is missing; a
        leaf folder is made :data:`~robocore.files.PRIVATE_DIR` when ``private``, as make_folder does."""
        if not parent:
            return self.root_fd
        if self.in_state and not made:
            make_folder(self.root / parent, private=self.private)
        parts = parent.split("/")
        fd = self.root_fd
        for index, part in enumerate(parts):
            leaf = index == len(parts) - 1
            key = "/".join(parts[:index + 1])
            if not leaf and key in self.kept:
                fd = self.kept[key]
                continue
            try:
                fd = os.open(part, _FOLDER, dir_fd=fd)
            except FileNotFoundError:
                if made:
                    raise
                make_folder(self.root / parent, private=self.private)  # every missing part, with its modes
                return self.open(parent, made=True)
            except OSError as exc:
                if exc.errno in (errno.ELOOP, errno.ENOTDIR):  # a link, or a file: refused in the usual words
                    check_no_links(self.root / parent, anchor=self.root)
                    make_folder(self.root / parent, private=self.private)
                raise
            if not leaf:
                self.kept[key] = fd
            elif self.private:
                try:
                    if stat.S_IMODE(os.fstat(fd).st_mode) != PRIVATE_DIR:
                        os.fchmod(fd, PRIVATE_DIR)
                except BaseException:
                    os.close(fd)
                    raise
        return fd

    def close(self) -> None:
        for fd in (*self.kept.values(), self.root_fd):
            os.close(fd)


def _fill(fd: int, data: bytes, folder_fd: int, name: str, mode: int | None) -> None:
    """Write ``data`` into the new file ``fd`` (``name`` in ``folder_fd``), give it ``mode`` (when the umask took bits
    of the mode it was created with) and close it; the file is removed when that fails."""
    try:
        with open(fd, "wb", closefd=True) as handle:
            handle.write(data)
            if mode is not None:
                os.fchmod(handle.fileno(), mode)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(name, dir_fd=folder_fd)
        raise


def _rewrite(folder_fd: int, path: Path, data: bytes, wanted: int) -> None:
    """The file already at ``path`` (``path.name`` in ``folder_fd``), as :func:`~robocore.files.write_atomic` treats
    it: refused when it is not a regular file; kept when it holds ``data`` and has no other link (its mode set to
    ``wanted``); else replaced by the rename of a new file (a file with another link, a hard link to a file
    elsewhere, is never changed in place)."""
    name = path.name
    info = os.stat(name, dir_fd=folder_fd, follow_symlinks=False)
    if not stat.S_ISREG(info.st_mode):
        raise UnsafePath(f"{path}: is not a regular file; robocore writes its own file there", hint=f"remove {path}")
    if info.st_nlink == 1 and info.st_size == len(data):
        with open(os.open(name, _READ, dir_fd=folder_fd), "rb", closefd=True) as handle:
            now = os.fstat(handle.fileno())
            if stat.S_ISREG(now.st_mode) and now.st_nlink == 1 and handle.read(len(data) + 1) == data:
                if stat.S_IMODE(now.st_mode) != wanted:
                    os.fchmod(handle.fileno(), wanted)
                return
    for _ in range(100):
        temporary = f".{name}.{os.urandom(4).hex()}.tmp"
        try:
            fd = os.open(temporary, _CREATE, wanted, dir_fd=folder_fd)
        except FileExistsError:
            continue
        _fill(fd, data, folder_fd, temporary, wanted)
        try:  # a rename replaces a name, never what a link there points to
            os.replace(temporary, name, src_dir_fd=folder_fd, dst_dir_fd=folder_fd)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(temporary, dir_fd=folder_fd)
            raise
        return
    raise FileExistsError(errno.EEXIST, f"no free temporary name next to {path}")
