"""Trees of files as the no-op memo (:mod:`robocore.commands.support.noop`) and the dev loop see them: one stat
row per entry, a digest of the rows, and the content hashes of the young files (changed too recently for their
times to show the next change).

The walk never leaves its boundary through a link: a symlink to a folder outside raises :class:`Untrusted` at
once (one ``realpath``, whatever the size of the tree behind it), and nothing outside is opened.
"""

from __future__ import annotations

import hashlib
import os
import stat
from collections.abc import Iterator, Sequence
from pathlib import Path

from robocore.files import STATE_DIR

#: Young files hashed for one snapshot at most, by count and by bytes; past either, no memo (the ordinary path).
MAX_YOUNG_FILES = 2000
MAX_YOUNG_BYTES = 64 << 20
#: Left out of every walk: Python's byte-code caches.
PYCACHE = "__pycache__"


class Snapshot:
    """What a task's result depends on: a digest of every entry's stat, and the content hashes of the young files.

    (Plain classes here: importing dataclasses costs more than this whole module's work.)"""

    def __init__(self, digest: str, young: dict[str, str]) -> None:
        self.digest = digest
        #: Relative path (``:robocore/...`` for robocore's own code) -> content hash, for every file changed since
        #: the snapshot's threshold (git's "racily clean" entries: their times alone cannot show a second change).
        self.young = young


class Untrusted(Exception):
    """The project cannot be snapshotted safely (a link to a folder outside it, too many young files to hash):
    no memo is read or written, the ordinary path runs."""


def _stat_row(rel: str, st: os.stat_result, link: str | None) -> str:
    if stat.S_ISDIR(st.st_mode):  # a folder's own times and size only repeat what the rows of its entries say
        return f"{rel}\0{st.st_mode}\0{st.st_ino}\0{st.st_dev}\0{link or ''}\n"
    return (f"{rel}\0{st.st_mode}\0{st.st_size}\0{st.st_ino}\0{st.st_dev}\0{st.st_mtime_ns}\0"
            f"{st.st_ctime_ns}\0{link or ''}\n")


def inside(real: str, boundary: str) -> bool:
    """True when the resolved path ``real`` is the resolved folder ``boundary`` or below it."""
    return real == boundary or real.startswith(boundary.rstrip("/") + "/")


def leads_outside(path: str, fence: str) -> bool:
    """True when the symlink at ``path`` resolves outside the resolved folder ``fence``. Said from the link's own
    text where that names a place outside (``cfg -> /root``: nothing outside is touched), else from its resolved
    path (a chain of links, which ``realpath`` follows by their metadata)."""
    named = os.path.normpath(os.path.join(os.path.realpath(os.path.dirname(path)), os.readlink(path)))
    return not inside(named, fence) or not inside(os.path.realpath(path), fence)


def tree_rows(root: Path, skipped: Sequence[str] = (), *, boundary: Path | None = None, stop_at_boundary: bool = False,
              ) -> Iterator[tuple[str, os.stat_result, str | None, os.stat_result | None]]:
    """``(relative path, lstat, link target or None, stat or None when broken)`` of every entry under ``root``,
    each folder once; ``skipped`` entries (relative paths) and Python's ``__pycache__`` folders are left out.

    Symlinked folders are walked when they resolve inside ``boundary`` (the project; None: anywhere). A symlink
    resolving to a folder outside it raises :class:`Untrusted` at once: the walk never leaves the project, and a
    link to a huge tree costs one ``realpath``. A symlink to anything else outside is listed with its target's
    stat (metadata only: nothing outside is opened). With ``stop_at_boundary`` (the dev loop's watch), a symlink
    leading outside, to a folder or anything else, is listed as a link (its own lstat and its text, its "stat" the
    lstat) and neither followed nor looked at through: nothing outside is watched."""
    fence = None if boundary is None else os.path.realpath(boundary)
    seen: set[tuple[int, int]] = set()
    pending = [(str(root), "")]
    while pending:
        folder, prefix = pending.pop()
        key = os.stat(folder)
        if (key.st_dev, key.st_ino) in seen:
            continue
        seen.add((key.st_dev, key.st_ino))
        with os.scandir(folder) as listing:
            names = sorted(entry.name for entry in listing)
        below = []
        for name in names:
            rel = prefix + name
            if name == PYCACHE or rel in skipped:
                continue
            path = os.path.join(folder, name)
            lst = os.lstat(path)
            link = None
            st: os.stat_result | None = lst
            if stat.S_ISLNK(lst.st_mode):
                link = os.readlink(path)
                if stop_at_boundary and fence is not None and leads_outside(path, fence):
                    yield rel, lst, link + "\0outside", lst
                    continue
                try:
                    st = os.stat(path)
                except OSError:
                    st = None
                if st is not None and stat.S_ISDIR(st.st_mode):
                    if fence is not None and not inside(os.path.realpath(path), fence):
                        raise Untrusted(f"{rel}: a symlink to a folder outside the project")
                    below.append((path, rel + "/"))
            elif stat.S_ISDIR(lst.st_mode):
                below.append((path, rel + "/"))
            yield rel, lst, link, st
        pending.extend(reversed(below))


def hash_file(path: str, budget: list[int]) -> str:
    """The sha256 of the regular file at ``path`` (never blocking on a FIFO); ``budget`` holds the bytes still
    allowed, and :class:`Untrusted` is raised past it."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY)
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        return "not-a-file"
    with os.fdopen(fd, "rb") as handle:
        digest = hashlib.sha256()
        while chunk := handle.read(1 << 20):
            budget[0] -= len(chunk)
            if budget[0] < 0:
                raise Untrusted("too many bytes changed in the last seconds to hash")
            digest.update(chunk)
        return digest.hexdigest()


def tree_digest(root: Path, skipped: Sequence[str], into: hashlib._Hash, *, boundary: Path | None = None,
                 stop_at_boundary: bool = False, young_after: float | None = None, young: dict[str, str] | None = None,
                 tag: str = "", budget: list[int] | None = None) -> None:
    """Feed ``into`` the stat rows of everything under ``root`` (:func:`tree_rows`, ``stop_at_boundary`` too: then
    a ``root`` that is itself a link leading outside counts by its own row only); with ``young``, hash into it
    (``tag`` + relative path -> sha256) every regular file changed at or after ``young_after``, within ``budget``
    bytes (shared between calls) and :data:`MAX_YOUNG_FILES` files, else :class:`Untrusted`."""
    fence = os.path.realpath(boundary) if boundary is not None else None
    if stop_at_boundary and fence is not None and not inside(os.path.realpath(root), fence):
        # a link leading outside: its own row (a retargeted link is seen), nothing behind it; a path through a
        # linked folder above it: not even that (its lstat would be of something outside)
        if inside(os.path.realpath(os.path.dirname(root)), fence) and os.path.islink(root):
            into.update(_stat_row(".\0outside", os.lstat(root), os.readlink(root)).encode())
        else:
            into.update(f"{root}\0outside\n".encode())
        return
    into.update(_stat_row(".", os.stat(root), None).encode())
    budget = [MAX_YOUNG_BYTES] if budget is None else budget
    for rel, lst, link, target in tree_rows(root, skipped, boundary=boundary, stop_at_boundary=stop_at_boundary):
        if rel == STATE_DIR and stat.S_ISDIR(lst.st_mode):
            continue  # made with the first memo: its entries count, its own row would spoil that memo
        st = lst
        if link is not None:
            if target is None:
                link += "\0broken"
            else:
                st = target
            into.update(_stat_row(rel + "\0lstat", lst, link).encode())
        into.update(_stat_row(rel, st, link).encode())
        if young is None or young_after is None or not stat.S_ISREG(st.st_mode):
            continue
        if max(st.st_mtime, st.st_ctime, lst.st_ctime) < young_after:
            continue
        path = os.path.join(root, rel)
        if link is not None and fence is not None and not inside(os.path.realpath(path), fence):
            raise Untrusted(f"{rel}: a symlink to a file outside the project, changed in the last seconds")
        if len(young) >= MAX_YOUNG_FILES:
            raise Untrusted("too many files changed in the last seconds to hash")
        young[tag + rel] = hash_file(path, budget)
