"""Opening the robot hosts' ssh connections before a command needs them.

A command line such as ``robocore build --component talker sync run`` spends its first few tenths of
a second importing its libraries and validating robot.yaml, and its remote steps then wait for
the ssh handshake with each robot host (about 0.2 s on a LAN). Both can happen at once:

- once a project is loaded, :func:`warm_loaded` starts the handshakes in the background (ssh
  ``ControlMaster``: the steps that follow share the connection) and records the hosts it warmed
  in ``.robocore/ssh-hosts.json``, beside the size and modification time of robot.yaml;
- the next command calls :func:`warm_recorded` first thing, before anything heavy is imported: if
  robot.yaml is unchanged, the recorded hosts are warmed at once.

Only command lines naming a remote step, and not a dry run (``--dry-run`` or ``-d``), warm anything. Warming never
waits and never reports: a host that cannot be reached is named by the step that needs it. The
record holds host names, users, addresses and ports, nothing secret. This module imports no
config model (pydantic), so that the CLI can call it before loading one.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

from robocore.project import ProjectFolder

#: Steps that talk to the robot hosts over ssh.
REMOTE_STEPS = frozenset({"dev", "sync", "run", "status", "logs", "connect", "doctor", "down", "rollback"})
#: Steps that connect to the robot hosts' Docker daemons with :func:`robocore.commands.support.hosts.connect`'s
#: settings (status and logs use others).
DOCKER_STEPS = frozenset({"dev", "run", "down", "rollback"})

#: The (user, ip, port) of every host this process has warmed: each is warmed once per process.
WARMED: set[tuple[str, str, int]] = set()


@dataclass(frozen=True)
class Endpoint:
    """A robot host as ssh sees it (satisfies :class:`robocore.adapters.ssh.Target`)."""

    name: str
    user: str
    ip: str
    ssh_port: int


def may_be_dry_run(argv: Sequence[str]) -> bool:
    """True when ``argv`` may ask for a dry run: ``--dry-run``, or a short flag such as ``-d`` or ``-qd``
    (the remote steps' short form of it). Read before the command line is parsed, so it errs on the side
    of a dry run: a dry run contacts no host, not even to warm a connection."""
    return any(arg == "--dry-run" or (arg[:1] == "-" and arg[1:2] != "-" and "d" in arg[1:]) for arg in argv)


def wants_remote(argv: Sequence[str]) -> bool:
    """True when ``argv`` names a step that will use the robot hosts, and is not a dry run."""
    return bool(REMOTE_STEPS & set(argv)) and not may_be_dry_run(argv)


def wants_docker(argv: Sequence[str]) -> bool:
    """True when ``argv`` names a step that will use the robot hosts' Docker daemons, and is not a dry run."""
    return bool(DOCKER_STEPS & set(argv)) and not may_be_dry_run(argv)


def warm(endpoints: Iterable[Endpoint]) -> None:
    """Start the ssh connections to ``endpoints`` not yet warmed by this process."""
    from robocore.adapters import ssh

    for endpoint in endpoints:
        key = (endpoint.user, endpoint.ip, endpoint.ssh_port)
        if key not in WARMED:
            WARMED.add(key)
            ssh.warm(endpoint)


def warm_loaded(root: Path, endpoints: Sequence[Endpoint], argv: Sequence[str]) -> None:
    """After loading the project in ``root``: warm ``endpoints`` (the ssh hosts that run something)
    when ``argv`` names a remote step, and record them for the next command's :func:`warm_recorded`."""
    if not wants_remote(argv):
        return
    warm(endpoints)
    record_warmed(root, endpoints)


def warm_recorded(argv: Sequence[str], cwd: Path | None = None) -> None:
    """First thing in the CLI: warm the hosts recorded for the project ``argv`` points at, when robot.yaml
    has not changed since they were recorded. Any doubt (no record, a changed file, a guess at the
    project folder that is wrong) warms nothing; nothing here raises."""
    if not wants_remote(argv):
        return
    from robocore.files import MAX_STATE_RECORD_BYTES, read_own_file

    try:
        root = _guess_project(argv, cwd or Path.cwd())
        record = ProjectFolder(root).ssh_hosts_record
        data = json.loads(read_own_file(record, limit=MAX_STATE_RECORD_BYTES) or b"{}")  # never a link, FIFO, huge file
        if data.get("robot_yaml") != _fingerprint(root):
            return
        endpoints = [Endpoint(str(e["name"]), str(e["user"]), str(e["ip"]), int(e["ssh_port"]))
                     for e in data["hosts"]]
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return
    warm(endpoints)


def _guess_project(argv: Sequence[str], cwd: Path) -> Path:
    """The project folder of a command line, without knowing the task names: ``-p DIR``, ``--project=DIR``,
    a leading ``DIR`` holding a record, else ``cwd``."""
    for i, arg in enumerate(argv):
        if arg in ("-p", "--project") and i + 1 < len(argv):
            return Path(argv[i + 1])
        if arg.startswith("--project="):
            return Path(arg.split("=", 1)[1])
    if argv and not argv[0].startswith("-") and ProjectFolder(Path(argv[0])).ssh_hosts_record.is_file():
        return Path(argv[0])
    return cwd


def _fingerprint(root: Path) -> list[int]:
    st = ProjectFolder(root).robot_file.stat()
    return [st.st_size, st.st_mtime_ns]


def record_warmed(root: Path, endpoints: Sequence[Endpoint]) -> None:
    """Record ``endpoints`` as the hosts warmed for the project at ``root``, so that the next command warms them."""
    from robocore.files import write_atomic

    try:
        text = json.dumps({"robot_yaml": _fingerprint(root), "hosts": [asdict(e) for e in endpoints]}) + "\n"
        write_atomic(ProjectFolder(root).ssh_hosts_record, text)  # rewritten only when it changes
    except OSError:
        pass  # a read-only project: the next command warms its hosts once it has loaded them
