"""The ``host:container`` strings of a component: ``devices``, ``volumes`` and ``ports``.

They reach Docker as they are written, so each part has a grammar: devices are absolute paths
under ``/dev``; volume sources are normalised absolute paths, project paths (``./config``) or
volume names; container paths are absolute and normalised; ports are numbers with an optional
IP address. Each check returns why an entry is malformed, or None.
"""

from __future__ import annotations

import posixpath
import re

from robocore.config.values import IPV4, IPV6, has_control, shown

_PORT_RE = re.compile(
    rf"(?:(?P<ip>{IPV4}|\[{IPV6}\]):)?(?P<host>[0-9]{{1,5}})(?:-(?P<host_end>[0-9]{{1,5}}))?"
    r":(?P<cont>[0-9]{1,5})(?:-(?P<cont_end>[0-9]{1,5}))?(?:/(?P<proto>tcp|udp|sctp))?"
)
_VOLUME_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")
_PERMISSIONS = re.compile(r"(?!.*(.).*\1)[rwm]{1,3}")


def port_pattern() -> re.Pattern[str]:
    """The regular expression that port mappings must match as a whole (use ``fullmatch``)."""
    return _PORT_RE


def _normalised_absolute(path: str) -> bool:
    return path.startswith("/") and not path.startswith("//") and posixpath.normpath(path) == path


def is_project_path(source: str) -> bool:
    """Whether a volume source is relative to the project folder (else absolute, or a named volume)."""
    return source.startswith(("./", "../")) or source in {".", ".."}


def device_problem(value: str) -> str | None:
    """Why a ``devices`` entry (``/dev/x[:/dev/y[:rwm]]``) is malformed, or None."""
    if has_control(value):
        return f"{shown(value)} holds control characters"
    parts = value.split(":")
    if not 1 <= len(parts) <= 3 or not parts[0].startswith("/"):
        return f"{shown(value)} is not host_path[:container_path[:rwm]] (host path must be absolute)"
    host = parts[0]
    if not _normalised_absolute(host) or not (host == "/dev" or host.startswith("/dev/")):
        return f"{shown(value)}: the host path must be a device under /dev (normalised, no '..')"
    if len(parts) >= 2 and not parts[1].startswith("/"):
        return f"{shown(value)}: container path must be absolute"
    if len(parts) >= 2 and not _normalised_absolute(parts[1]):
        return f"{shown(value)}: container path must be normalised (no '..', '.' or '//')"
    if len(parts) == 3 and not _PERMISSIONS.fullmatch(parts[2]):
        return f"{shown(value)}: permissions must be letters of 'rwm'"
    return None


def volume_problem(value: str) -> str | None:
    """Why a ``volumes`` entry (``source:/container/path[:ro|rw]``) is malformed, or None."""
    if has_control(value):
        return f"{shown(value)} holds control characters"
    parts = value.split(":")
    if not 2 <= len(parts) <= 3 or not parts[0] or not parts[1].startswith("/"):
        return f"{shown(value)} is not host_path:container_path[:ro|rw] (container path must be absolute)"
    source, target = parts[0], parts[1]
    if source.startswith("/"):
        if not _normalised_absolute(source):
            return f"{shown(value)}: the host path must be normalised (no '..', '.' or '//')"
    elif is_project_path(source) and posixpath.normpath(source).split("/")[0] == "..":
        return (f"{shown(value)}: a project path that leaves the project folder means nothing on a robot; "
                f"name a host folder by its absolute path ({shown(posixpath.normpath(source))} is not in the project)")
    elif not is_project_path(source) and not _VOLUME_NAME.fullmatch(source):
        return (f"{shown(value)}: the source must be an absolute path, a project path (./path) or a volume name "
                "(letters, digits, '_', '.', '-')")
    if target == "/" or not _normalised_absolute(target):
        return f"{shown(value)}: container path must be a normalised folder other than / (no '..', '.' or '//')"
    if len(parts) == 3 and parts[2] not in {"ro", "rw"}:
        return f"{shown(value)}: mode must be ro or rw"
    return None


def port_problem(value: str) -> str | None:
    """Why a ``ports`` entry is malformed, or None."""
    match = _PORT_RE.fullmatch(value)
    if not match:
        return f"{shown(value)} is not [ip:]host_port:container_port[/tcp|udp]"
    numbers = [match.group(g) for g in ("host", "host_end", "cont", "cont_end") if match.group(g)]
    if any(not 1 <= int(n) <= 65535 for n in numbers):
        return f"{shown(value)}: ports must be between 1 and 65535"
    host_end, cont_end = match.group("host_end"), match.group("cont_end")
    if host_end and int(host_end) < int(match.group("host")):
        return f"{shown(value)}: port range ends before it starts"
    if cont_end and int(cont_end) < int(match.group("cont")):
        return f"{shown(value)}: port range ends before it starts"
    if (host_end or cont_end) and (
        int(host_end or match.group("host")) - int(match.group("host"))
        != int(cont_end or match.group("cont")) - int(match.group("cont"))
    ):
        return f"{shown(value)}: host and container port ranges differ in length"
    return None


def read_only_project_path(volume: str) -> str | None:
    """The normalized project-relative path (``config/params``) of a read-only project volume
    (``./config/params:/params:ro``), which sync copies to remote hosts; None for any other volume."""
    parts = volume.split(":")
    if len(parts) < 3 or parts[2] != "ro" or not is_project_path(parts[0]):
        return None
    return posixpath.normpath(parts[0])


#: Host paths whose mount hands a container the Docker daemon (and so the whole host).
DOCKER_SOCKETS = ("/var/run/docker.sock", "/run/docker.sock")
#: Device names of disks and partitions: a container that can write them can rewrite the host.
_BLOCK_DEVICE = re.compile(
    r"/dev/(?:sd[a-z]|hd[a-z]|vd[a-z]|xvd[a-z]|nvme[0-9]|mmcblk[0-9]|loop[0-9]|dm-[0-9]|md[0-9]|mapper/|disk/)"
)


#: System folders of a host: a container that writes them changes the host (its configuration, kernel, boot).
SYSTEM_FOLDERS = ("/etc", "/proc", "/sys", "/boot", "/usr", "/lib", "/bin", "/sbin", "/var/lib/docker", "/dev")
#: Host folders whose mount hands a container the host itself: the system folders and root's home (its keys).
HOST_FOLDERS = (*SYSTEM_FOLDERS, "/root")
#: Devices that give the host's memory, I/O ports or flash (besides disks).
_HOST_DEVICE = re.compile(r"/dev/(?:mem|kmem|port|mtd[0-9]|mtdblock[0-9]|ubi[0-9]|nvram|sg[0-9]|bsg/|watchdog)")


def owns_host_folder(source: str, folders: tuple[str, ...] = HOST_FOLDERS) -> str | None:
    """The folder of ``folders`` that ``source`` (absolute, normalised) is or lies in, else None."""
    return next((folder for folder in folders if source == folder or source.startswith(folder + "/")), None)


def is_host_device(path: str) -> bool:
    """True for a device that gives the host's memory, ports or flash (``/dev/mem``, ``/dev/mtd0``)."""
    return _HOST_DEVICE.match(path) is not None


def exposes_docker_socket(source: str) -> bool:
    """True when a bind mount of ``source`` (absolute) contains the Docker daemon's socket."""
    return any(socket == source or socket.startswith(source.rstrip("/") + "/") for socket in DOCKER_SOCKETS)


def is_block_device(path: str) -> bool:
    """True for a disk or partition device (``/dev/sda1``, ``/dev/nvme0n1``, ``/dev/mmcblk0p2``)."""
    return _BLOCK_DEVICE.match(path) is not None
