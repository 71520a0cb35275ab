"""Which hosts a command works on, their Docker connections, and work done side by side.

Every command that touches several hosts (run, down, sync, status, logs, doctor, rollback) goes
through :func:`for_each_host`: each host is tried, a host that fails is named with its error and
does not stop the others. Local work that runs side by side (image builds, colcon builds and
tests, one container each) goes through :func:`in_parallel`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TYPE_CHECKING, Any, TypeVar

from robocore.adapters.docker_hosts import is_connection_error
from robocore.commands.support.status_table import managed
from robocore.config.model import Host
from robocore.errors import HostError, RobocoreError
from robocore.plan import naming
from robocore.project import Project

if TYPE_CHECKING:
    import docker

T = TypeVar("T")
R = TypeVar("R")

#: Seconds a host gets to answer before it is reported unreachable.
HOST_CONNECT_TIMEOUT = 8
#: Seconds each Docker API call to a host may take.
CONNECT_API_TIMEOUT = 300


def select_hosts(project: Project, host: str | None) -> list[Host]:
    """``--host NAME`` (checked), else every host of the robot."""
    return [project.host(host)] if host else list(project.robot.hosts)


def connect(project: Project, host: Host, *, timeout: int = CONNECT_API_TIMEOUT) -> docker.DockerClient:
    """The Docker client of ``host`` (HostError naming the host when it cannot be reached)."""
    from robocore.adapters.docker_hosts import client_for

    return client_for(host, timeout, project_root=project.root, connect_timeout=HOST_CONNECT_TIMEOUT)


def prefetch_connections(project: Project) -> None:
    """Start :func:`connect`'s connection to every ssh host that runs something, in the background."""
    from robocore.adapters.docker_hosts import prefetch

    for host in project.robot.hosts_in_use():
        prefetch(host, CONNECT_API_TIMEOUT, connect_timeout=HOST_CONNECT_TIMEOUT)


def managed_containers(client: docker.DockerClient, project: str) -> list[Any]:
    """This project's component and discovery containers on a host (running or not).

    Known by label and by the ``<project>-`` name robocore gives them: a build's intermediate containers inherit
    the labels of the image they start from, and one removed meanwhile (another terminal's ``down``) is left out."""
    found = client.containers.list(all=True, filters={"label": f"{naming.LABEL_PROJECT}={project}"},
                                   ignore_removed=True)
    return [c for c in found
            if c.labels.get(naming.LABEL_ROLE) in naming.MANAGED_ROLES and (c.name or "").startswith(f"{project}-")]


def running_container(client: docker.DockerClient, name: str) -> Any:
    """The container ``name`` on ``client``'s host when it is running, else None (status --nodes, connect)."""
    from docker.errors import NotFound

    try:
        container = client.containers.get(name)
    except NotFound:
        return None
    return container if container.status == "running" else None


def local_documents(project: Project, host: Host) -> list[dict[str, Any]] | None:
    """The inspect documents of the project's managed containers on a local host, read over the daemon's unix
    socket without docker-py (whose import was most of a status' time); None for other hosts or when the
    socket does not answer (docker-py is asked then)."""
    if not host.is_local:
        return None
    from robocore.adapters import docker_socket

    found = docker_socket.containers(f"{naming.LABEL_PROJECT}={project.name}")
    if found is None:
        return None
    return managed(found)


def managed_documents(project: Project, host: Host) -> list[dict[str, Any]]:
    """The inspect documents of :func:`managed_containers` on ``host``, through docker-py."""
    client = connect(project, host, timeout=60)
    try:
        return [dict(c.attrs) for c in managed_containers(client, project.name)]
    finally:
        client.close()


def short_error(exc: BaseException) -> str:
    """The first line of what an exception says (docker-py's explanation when it has one)."""
    explanation = getattr(exc, "explanation", None)
    text = str(explanation or exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def in_parallel(items: Sequence[T], work: Callable[[T], R], *, limit: int,
                name: str = "robocore") -> list[tuple[T, R | BaseException]]:
    """``work(item)`` for every item, at most ``limit`` at a time; each item with its result or the
    exception it raised, in the order of ``items``. Every item is tried, whatever the others do."""
    if not items:
        return []
    from robocore.adapters.docker_hosts import load_client_modules

    load_client_modules()  # the threads below make Docker clients: no two of them import docker-py at once
    done: list[tuple[T, R | BaseException]] = []
    with ThreadPoolExecutor(max_workers=max(1, min(limit, len(items))), thread_name_prefix=name) as pool:
        futures = [(item, pool.submit(work, item)) for item in items]
        for item, future in futures:
            try:
                done.append((item, future.result()))
            except BaseException as exc:  # collected: the others still run to their end
                done.append((item, exc))
    return done


def each_or_first_error(items: Sequence[T], work: Callable[[T], object], *, limit: int, name: str = "robocore") -> None:
    """``work(item)`` for every item, at most ``limit`` at a time (:func:`in_parallel`); once every item has been
    tried, the first exception, in the order of ``items``, is raised."""
    for _item, outcome in in_parallel(items, work, limit=limit, name=name):
        if isinstance(outcome, BaseException):
            raise outcome


def for_each_host(hosts: Sequence[Host], work: Callable[[Host], T]) -> tuple[dict[str, T], dict[str, RobocoreError]]:
    """Run ``work(host)`` for every host in parallel; return (results, failures) by host name.

    Docker and network errors become a HostError of that host; other exceptions are bugs and
    are raised once every host has finished.
    """
    results: dict[str, T] = {}
    failures: dict[str, RobocoreError] = {}
    bugs: list[BaseException] = []
    for host, outcome in in_parallel(hosts, work, limit=len(hosts), name="robocore-host"):
        if isinstance(outcome, RobocoreError):
            failures[host.name] = outcome
        elif isinstance(outcome, Exception) and is_connection_error(outcome):
            failures[host.name] = HostError(f"host {host.name}: {short_error(outcome)}")
        elif isinstance(outcome, BaseException):
            bugs.append(outcome)
        else:
            results[host.name] = outcome
    if bugs:
        raise bugs[0]
    return results, failures


def lock_refused(host: Host, code: int, stderr: str, *, busy: str, again: str, locks: str) -> RobocoreError | None:
    """What a host's lock script's exit ``code`` means (``ssh.hold``'s ``refused``): the lock held by another
    robocore (``busy``, with the holder's line from ``stderr``; retry with ``again``), flock missing (it
    ``locks`` those), or None for any other failure."""
    from robocore.plan.sync import LOCK_BUSY

    if code == LOCK_BUSY:
        holder = stderr.strip().splitlines()[-1] if stderr.strip() else "another robocore"
        return HostError(f"host {host.name}: {busy}: {holder}", hint=f"wait for it to finish, then {again} again")
    if code == 127:
        return HostError(f"host {host.name}: flock is not installed there (robocore locks {locks} with it)",
                         hint="install util-linux on the host (apt-get install util-linux)")
    return None


def lock_holder() -> str:
    """Who holds a host's lock (a sync or a build there), for a developer who finds it taken: user@machine,
    pid and time."""
    import getpass
    import os
    import socket
    import time

    try:
        user = getpass.getuser()
    except (KeyError, OSError):
        user = str(os.getuid())
    return f"{user}@{socket.gethostname()} (pid {os.getpid()}) since {time.strftime('%Y-%m-%d %H:%M:%S %Z')}"
