"""The sync plan: which files go to which host, and the exact commands that move them (pure).

On a remote host every component gets ``<mount_root>/<component>/``::

    releases/<id>/install/      colcon install tree (built on the dev machine, or on the host itself:
                                copied there from the host's build folder, see plan/remote_build.py)
    releases/<id>/dds/          generated Fast DDS profiles
    releases/<id>/<host>.yaml   the host's compose file (also hard-linked as compose.yaml)
    releases/<id>/files/<path>  read-only project volumes (``./config:/config:ro``), from the project
    staging/                    the release being copied (absent when idle)
    current -> releases/<id>    switched atomically once a release is complete

A sync's remote side is one ssh session per host (:data:`SESSION_SCRIPT`), plus one rsync per
component whose tree may differ. The session (1) takes the host's sync lock and reports, per
component, whether an interrupted ``staging`` is there and where ``current`` points; then robocore
(2) rsyncs into ``staging`` with ``--link-dest`` against ``current``, so unchanged files become
hard links and changed ones move as rsync deltas; then the session (3) renames ``staging`` to
``releases/<id>``, switches ``current`` with ``ln -s`` to a temp name and ``mv -T`` (a rename(2),
atomic), and prunes old releases. If anything stops before (3), ``current`` still names the
previous complete release and the next sync reuses the partial ``staging``. A copy that turns out
unchanged is dropped and ``current`` kept; a component whose local tree has the same quick-check
digest (paths, sizes, mtimes, modes) as the release ``current`` names is not rsynced at all.

One sync at a time per host: the session holds ``flock`` on ``<mount_root>/.robocore-sync.lock``
there from (1) to (3), so two developers syncing to one robot never write into the same
``staging``; the second is told who holds it and stops. The lock lives as long as the ssh session
that holds it: it is released when robocore ends, however it ends.

Remote steps are argv lists: a fixed POSIX sh script run with ``sh -c SCRIPT sh ARG...``, its
arguments passed as positional parameters, never interpolated into the script.
"""

from __future__ import annotations

import hashlib
import os
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path, PurePosixPath

from robocore.config.model import Host
from robocore.errors import HostError
from robocore.plan.addresses import bare, bracketed

#: Complete releases kept per component (the current one always among them).
KEEP_RELEASES = 3
STAGING = "staging"
RELEASES = "releases"
CURRENT = "current"
_RELEASE_RE = re.compile(r"^\d{8}T\d{6}Z-[0-9a-f]{6}$")

#: Exit code of :data:`SESSION_SCRIPT` when another sync holds the host's lock.
LOCK_BUSY = 75
LOCK_FILE = ".robocore-sync.lock"
#: Printed by :data:`SESSION_SCRIPT` once it holds the lock (after the prepare lines).
LOCKED = "robocore-sync-locked"
#: Printed by :data:`SESSION_SCRIPT` once it carried out the last instruction.
DONE = "robocore-sync-done"
#: What the last instruction may ask of each component, in the order of the session's arguments.
RELEASE, DISCARD, KEEP = "release", "discard", "keep"

# A whole sync's remote side in one ssh session. Arguments: the host's mount root, a line saying
# who syncs, the releases to keep, then (component root, compose file name or "") pairs.
#  1. lock: an exclusive flock on <mount root>/.robocore-sync.lock, held until the script ends, the
#     holder line written beside it. If another process holds it: that holder's line on stderr, exit
#     LOCK_BUSY at once.
#  2. prepare: for each component, creates its releases/ folder and prints "staging=<0|1>" (an
#     interrupted copy is there) and "current=<target of current>"; then prints LOCKED.
#  3. waits for one line on stdin: a release id, then RELEASE, DISCARD or KEEP for each component.
#     RELEASE renames staging to releases/<id>, switches current to it with a rename, prunes old
#     releases; DISCARD removes staging (an unchanged copy); KEEP leaves the component alone. Prints
#     DONE. If stdin ends first (robocore died), nothing is switched: staging is resumed next time.
#: Shell lines shared by every script that takes a host's sync lock (``$mount_root`` and ``$holder`` set):
#: exit LOCK_BUSY with the holder's line on stderr when another robocore holds it, else record the holder.
TAKE_LOCK = f"""\
mkdir -p -- "$mount_root"
lock="$mount_root/{LOCK_FILE}"
exec 9>>"$lock"
code=0
flock -n -E {LOCK_BUSY} 9 || code=$?
if [ "$code" -ne 0 ]; then
    if [ "$code" -eq {LOCK_BUSY} ]; then cat -- "$lock.holder" >&2 2>/dev/null || true; fi
    exit "$code"
fi
printf '%s\\n' "$holder" > "$lock.holder"
"""

SESSION_SCRIPT = f"""\
set -eu
mount_root=$1; holder=$2; keep=$3; shift 3
case $keep in ''|*[!0-9]*) echo "releases to keep: not a number: $keep" >&2; exit 64;; esac
{TAKE_LOCK}root=
for arg in "$@"; do
    if [ -z "$root" ]; then root=$arg; continue; fi
    mkdir -p -- "$root/releases"
    if [ -d "$root/staging" ]; then echo staging=1; else echo staging=0; fi
    if [ -L "$root/current" ]; then echo "current=$(readlink -- "$root/current")"; else echo current=; fi
    root=
done
echo {LOCKED}
IFS=' ' read -r id steps || exit 0
case $id in ''|*[!0-9A-Za-z-]*) echo "not a release id: $id" >&2; exit 64;; esac
root=
for arg in "$@"; do
    if [ -z "$root" ]; then root=$arg; continue; fi
    compose=$arg; dir=$root; root=
    step=${{steps%% *}}; steps=${{steps#"$step"}}; steps=${{steps# }}
    case $step in
    {KEEP}) ;;
    {DISCARD}) rm -rf -- "$dir/staging" ;;
    {RELEASE}) (
        cd -- "$dir"
        if [ -n "$compose" ] && [ -f "staging/$compose" ]; then ln -f -- "staging/$compose" staging/compose.yaml; fi
        mv -T -- staging "releases/$id"
        rm -f -- .current.tmp
        ln -s -- "releases/$id" .current.tmp
        mv -T -- .current.tmp current
        live=$(readlink -- current)
        ls -1 releases | sort -r | tail -n "+$((keep + 1))" | while IFS= read -r old; do
            [ "releases/$old" = "$live" ] || rm -rf -- "releases/$old"
        done
    ) ;;
    *) echo "unknown step for $dir: '$step'" >&2; exit 64 ;;
    esac
done
echo {DONE}
"""


@dataclass(frozen=True)
class Source:
    """One local file or folder to copy, and where it lands inside the release."""

    path: Path  # absolute local path
    name: str  # name inside the release (install, dds, <host>.yaml, files)
    #: A folder of symlinks to what is really copied (the project files): rsync copies what they point to.
    follow: bool = False

    @property
    def rsync_arg(self) -> str:
        """``parent/./name`` (folders without a trailing slash): rsync ``-R`` keeps ``name``."""
        return f"{self.path.parent}/./{self.path.name}"


@dataclass(frozen=True)
class ComponentSync:
    """Everything needed to sync one component to its host."""

    component: str
    host: str
    root: PurePosixPath  # <mount_root>/<component> on the host
    sources: tuple[Source, ...]
    compose_name: str  # name of the compose file inside the release ("" when none)
    #: Built on its host (``builds_here``): the host's install tree, copied into the release on the host.
    install_on_host: PurePosixPath | None = None
    #: The id of that build (part of the quick check: a new build on the host is a new tree).
    host_build_id: str = ""

    @property
    def staging(self) -> PurePosixPath:
        """Where rsync writes."""
        return self.root / STAGING

    @property
    def current(self) -> PurePosixPath:
        """The symlink to the live release."""
        return self.root / CURRENT


def new_release_id(now: datetime | None = None, nonce: bytes | None = None) -> str:
    """A sortable, unique release id: ``20260101T120000Z-1a2b3c``."""
    now = (now or datetime.now(timezone.utc)).astimezone(timezone.utc)
    suffix = hashlib.sha256(nonce if nonce is not None else os.urandom(8)).hexdigest()[:6]
    return f"{now:%Y%m%dT%H%M%SZ}-{suffix}"


def is_release_id(text: str) -> bool:
    """True for ids made by :func:`new_release_id`."""
    return bool(_RELEASE_RE.match(text))


def remote_sh(script: str, *args: str) -> list[str]:
    """``sh -c SCRIPT sh ARG...``: a fixed script with its arguments as positional parameters."""
    return ["sh", "-c", script, "sh", *args]


def session_argv(mount_root: str, holder: str, items: Sequence[ComponentSync], keep: int = KEEP_RELEASES) -> list[str]:
    """Remote argv of a whole sync's remote side (see :data:`SESSION_SCRIPT`): lock, prepare ``items``,
    then wait for :func:`finish_line`. ``holder`` (who, from where, when) is left beside the lock for
    whoever finds it taken."""
    pairs = [arg for i in items for arg in (str(i.root), i.compose_name)]
    return remote_sh(SESSION_SCRIPT, mount_root, holder, str(max(1, keep)), *pairs)


def parse_prepare(lines: Sequence[str], count: int) -> list[dict[str, str]]:
    """The ``staging``/``current`` pairs the session printed before it was locked, one dict per item."""
    rows = [plain for plain in lines if "=" in plain]
    if len(rows) != 2 * count:
        raise ValueError(f"expected {2 * count} lines from the prepare step, got {len(rows)}")
    return [parse_keyvals("\n".join(rows[2 * i: 2 * i + 2])) for i in range(count)]


def finish_line(release_id: str, steps: Sequence[str]) -> str:
    """The session's last instruction: ``release_id``, then RELEASE, DISCARD or KEEP per item, in order."""
    if not is_release_id(release_id):
        raise ValueError(f"not a release id: {release_id!r}")
    unknown = set(steps) - {RELEASE, DISCARD, KEEP}
    if unknown:
        raise ValueError(f"unknown sync steps: {sorted(unknown)}")
    return " ".join([release_id, *steps])


def remote_path(host: Host, path: str) -> str:
    """rsync's ``user@host:path`` of ``path`` on ``host``, an IPv6 address in brackets (``fe80::1:/x``
    would be read as rsync's daemon syntax). A user or address starting with ``-`` is refused: rsync
    hands both to ssh as arguments."""
    if host.user.startswith("-") or bare(host.ip).startswith("-"):
        raise HostError(f"host {host.name}: user {host.user!r} or address {host.ip!r} starts with '-'",
                        hint="fix the host's user and ip in robot.yaml")
    return f"{host.user}@{bracketed(host.ip)}:{path}"


def rsync_argv(item: ComponentSync, host: Host, rsh: str, *, io_timeout: int = 60) -> list[str]:
    """The local rsync argv copying ``item``'s sources into ``staging`` on ``host``.

    ``-a`` keeps modes and times (the quick check), ``-s`` (``--protect-args``) hands paths and
    options to the remote rsync as they are instead of through the remote shell, ``--delete``
    removes files gone locally, ``--copy-unsafe-links`` turns symlinks that leave the tree (read-only
    project volumes) into the files they point to (sync checked first that they stay in the project),
    ``--link-dest`` hard-links what is unchanged in ``current``, ``--stats`` reports the bytes moved.
    The operands follow ``--``.
    """
    return [
        "rsync",
        "-a",
        "-R",
        "-s",
        "--delete",
        "--copy-unsafe-links",
        "--stats",
        f"--timeout={io_timeout}",
        f"--link-dest={item.current}/",
        "-e",
        rsh,
        "--",
        *(s.rsync_arg for s in item.sources),
        remote_path(host, f"{item.staging}/"),
    ]


@dataclass(frozen=True)
class RsyncStats:
    """What ``rsync --stats`` reported."""

    files: int = 0
    created: int = 0
    deleted: int = 0
    transferred: int = 0
    literal: int = 0
    sent: int = 0
    received: int = 0

    @property
    def changed(self) -> bool:
        """True when the copy differs from the link-dest release (new, changed or deleted files)."""
        return bool(self.created or self.transferred or self.deleted)


_STAT_KEYS = {
    "Number of files": "files",
    "Number of created files": "created",
    "Number of deleted files": "deleted",
    "Number of regular files transferred": "transferred",
    "Literal data": "literal",
    "Total bytes sent": "sent",
    "Total bytes received": "received",
}


def parse_stats(output: str) -> RsyncStats:
    """Read the numbers of ``rsync --stats`` output (rsync 3.1+, with or without thousands separators)."""
    values: dict[str, int] = {}
    for line in output.splitlines():
        key, sep, rest = line.partition(":")
        field = _STAT_KEYS.get(key.strip())
        if field is None or not sep:
            continue
        match = re.match(r"\s*([\d,.]+)", rest)
        if match:
            values[field] = int(re.sub(r"[,.]", "", match.group(1)))
    return RsyncStats(**values)


def parse_keyvals(output: str) -> dict[str, str]:
    """``key=value`` lines printed by the remote scripts."""
    out: dict[str, str] = {}
    for line in output.splitlines():
        key, sep, value = line.partition("=")
        if sep:
            out[key.strip()] = value.strip()
    return out


def manifest_digest(entries: Iterable[tuple[str, int, int, int, str]]) -> str:
    """Digest of (relative path, size, mtime_ns, mode, link target) rows: rsync's quick-check view of a tree."""
    digest = hashlib.sha256()
    for row in sorted(entries):
        digest.update(repr(row).encode())
        digest.update(b"\n")
    return digest.hexdigest()
