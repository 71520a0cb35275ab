"""Builds on the robot (a host with ``builds_here: true``): where things live there, and the commands (pure).

A component of such a host is built on the host itself, natively, instead of on the dev machine (under
emulation when the arches differ). Its host keeps one persistent build folder per component::

    <mount_root>/<component>/work/ws/        the workspace, sent with rsync (only what changed moves)
    <mount_root>/<component>/work/build/     colcon's build folder (kept: incremental builds stay incremental)
    <mount_root>/<component>/work/install/   colcon's install tree (kept; sync releases it from here)
    <mount_root>/<component>/work/log/       colcon's logs
    <mount_root>/<component>/work/ccache/    ccache's cache, when the image has ccache

``build`` holds the host's sync lock (the same ``flock`` that sync takes, :mod:`robocore.plan.sync`) while it
sends the workspace and runs colcon, in the component's image on the host's Docker daemon, as the ssh user.
``sync`` then copies ``work/install`` into the release's ``staging/install`` on the host itself (rsync on the
host, hard links to the ``current`` release for what did not change), so the tree never travels through the
dev machine, and switches ``current`` as for any other component.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from robocore.config.model import Host
from robocore.plan import colcon, naming
from robocore.plan.arches import INSTALL_ARCH_FILE
from robocore.plan.layout import component_root
from robocore.plan.sync import CURRENT, STAGING, TAKE_LOCK, remote_path, remote_sh

WORK = "work"
#: Printed by :data:`LOCK_SCRIPT` once it holds the host's lock (after the ``uid=``/``gid=`` lines).
LOCKED = "robocore-build-locked"
#: Printed by :data:`LOCK_SCRIPT` when it lets the lock go.
DONE = "robocore-build-done"
#: The last line :data:`LOCK_SCRIPT` reads after a successful build: the arch to record in the install tree.
ARCH_PREFIX = "arch="

#: Top-level names of a workspace that are never sent (colcon's own output) and names never sent anywhere
#: in it (hidden files and folders, byte code): what :func:`robocore.commands.support.workspace.workspace_files` skips.
_TOP_EXCLUDES = ("/build/", "/install/", "/log/")
_EXCLUDES = (".*", "*.pyc", "*.pyo", "__pycache__/")

# The host's side of a build. Arguments: the mount root, a line saying who builds, then the component's work
# folder. Takes the host's sync lock (exit LOCK_BUSY with the holder's line on stderr when taken), makes the
# work folders (so that Docker does not make them as root), prints the ssh user's uid and gid, then LOCKED;
# keeps the lock until a line (or the end of) stdin: "arch=<arch>" after a successful build writes the arch
# into the install tree (robocore.plan.arches.INSTALL_ARCH_FILE), anything else writes nothing; prints DONE.
LOCK_SCRIPT = f"""\
set -eu
mount_root=$1; holder=$2; work=$3
{TAKE_LOCK}mkdir -p -- "$work/ws" "$work/build" "$work/install" "$work/log" "$work/ccache"
echo "uid=$(id -u)"
echo "gid=$(id -g)"
echo {LOCKED}
line=
read -r line || true
case $line in
{ARCH_PREFIX}*)
    arch=${{line#{ARCH_PREFIX}}}
    case $arch in ''|*[!a-z0-9_]*) echo "not an arch: $arch" >&2; exit 64;; esac
    printf '%s\n' "$arch" > "$work/install/{INSTALL_ARCH_FILE}" ;;
esac
echo {DONE}
"""


# $1: the current release's install tree (--link-dest), $2: the host's install tree, $3: the staging one.
RELEASE_SCRIPT = """\
set -eu
mkdir -p -- "$3"
exec rsync -a --delete --stats "--link-dest=$1" -- "$2" "$3"
"""


@dataclass(frozen=True)
class HostBuild:
    """Where one component is built on its host."""

    component: str
    host: str
    root: PurePosixPath  # <mount_root>/<component>

    @property
    def work(self) -> PurePosixPath:
        """The persistent build folder."""
        return self.root / WORK

    @property
    def workspace(self) -> PurePosixPath:
        """Where the workspace is sent."""
        return self.work / "ws"

    @property
    def install(self) -> PurePosixPath:
        """colcon's install tree on the host."""
        return self.work / "install"

    def mounts(self, *, ccache: bool) -> dict[str, str]:
        """``{host path: container path}`` of the build container on the host: the same container paths as
        a build on the dev machine (:func:`robocore.plan.colcon.workspace_mounts`)."""
        mounts = {
            str(self.workspace): naming.CONTAINER_WS,
            str(self.work / "build"): colcon.CONTAINER_BUILD,
            str(self.install): naming.CONTAINER_INSTALL,
            str(self.work / "log"): colcon.CONTAINER_LOG,
        }
        if ccache:
            mounts[str(self.work / "ccache")] = colcon.CONTAINER_CCACHE
        return mounts


def builds_on_host(host: Host) -> bool:
    """True when ``host``'s components are built on the host itself."""
    return host.builds_here and not host.is_local


def host_build(host: Host, component: str) -> HostBuild:
    """Where ``component`` is built on ``host``."""
    return HostBuild(component=component, host=host.name, root=component_root(host, component))


def lock_argv(host: Host, holder: str, build: HostBuild) -> list[str]:
    """Remote argv of :data:`LOCK_SCRIPT` for ``build``: the lock held while the workspace moves and colcon runs."""
    return remote_sh(LOCK_SCRIPT, host.deploy_root, holder, str(build.work))


def parse_ids(greeting: Sequence[str]) -> str:
    """``uid:gid`` from the lines :data:`LOCK_SCRIPT` printed before it was locked; ValueError when absent."""
    values = dict(line.strip().split("=", 1) for line in greeting if "=" in line)
    uid, gid = values.get("uid", ""), values.get("gid", "")
    if not (uid.isdigit() and gid.isdigit()):
        raise ValueError(f"no uid=/gid= lines in {list(greeting)!r}")
    return f"{uid}:{gid}"


def finish_line(arch: str | None) -> str:
    """The line that lets :data:`LOCK_SCRIPT` go: with ``arch`` (a successful build), it records it in the install
    tree first."""
    if arch is None:
        return "done"
    if not arch.isalnum():
        raise ValueError(f"not an arch: {arch!r}")
    return f"{ARCH_PREFIX}{arch}"


def workspace_rsync_argv(workspace: Path, build: HostBuild, host: Host, rsh: str, *,
                         skip_dirs: Sequence[str] = (), io_timeout: int = 60) -> list[str]:
    """The local rsync argv sending ``workspace`` to the host's ``work/ws`` (deltas only; files gone locally
    are deleted there; colcon's output folders, hidden files, byte code and ``skip_dirs`` are never sent;
    symlinks that leave the workspace are sent as what they point to, which build checked stays in the
    project). The operands follow ``--``."""
    excludes = [f"--exclude={pattern}" for pattern in (*_TOP_EXCLUDES, *_EXCLUDES)]
    excludes += [f"--exclude={name}/" for name in sorted(skip_dirs)]
    return [
        "rsync", "-a", "-s", "--delete", "--delete-excluded", "--copy-unsafe-links", "--stats",
        f"--timeout={io_timeout}", *excludes, "-e", rsh, "--",
        f"{workspace}/", remote_path(host, f"{build.workspace}/"),
    ]


def release_install_argv(build: HostBuild) -> list[str]:
    """Remote argv (run on the host, under sync's lock) copying the host's install tree into the release
    being made: hard links to the ``current`` release for unchanged files, a new file for each changed
    one (rsync writes a temp file and renames it, so no earlier release is ever changed in place)."""
    return remote_sh(RELEASE_SCRIPT, f"{build.root / CURRENT / 'install'}/", f"{build.install}/",
                     f"{build.root / STAGING / 'install'}/")


def fetch_install_argv(build: HostBuild, host: Host, rsh: str, local_install: Path, *,
                       io_timeout: int = 60) -> list[str]:
    """The local rsync argv bringing the host's install tree back to the dev machine (for ``shell``)."""
    return [
        "rsync", "-a", "-s", "--delete", "--stats", f"--timeout={io_timeout}", "-e", rsh, "--",
        remote_path(host, f"{build.install}/"), f"{local_install}/",
    ]
