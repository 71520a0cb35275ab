"""``fleet logs ROBOT [--component C] [--follow]``: a robot's logs read through the Swarm manager only.

Each service of the robot (its discovery servers and components, or the one ``--component`` names) is read with
Swarm's service logs: the manager asks the agent of the node that runs the task, so no connection to the robot is
made from here, and the robot needs no ssh. Each line is printed behind its component, as ``robocore logs`` does;
``--follow`` merges the live streams until interrupted. A robot whose node is down cannot send its logs (the manager
would wait for its agent): its services on that host are named and skipped.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from robocore.adapters import swarm, swarm_tasks
from robocore.commands.fleet_swarm import FleetProject, load, manager_line, offline, robot_nodes
from robocore.commands.logs import LOG_STREAM_TIMEOUT, LogLine, emit_line, follow_logs, split_lines
from robocore.commands.support.context import Options
from robocore.errors import HostError
from robocore.plan.fleet_parts import Part, robot_parts

if TYPE_CHECKING:
    from collections.abc import Iterator

    import docker

#: Lines of each task's log shown first (as ``robocore logs``' default ``--tail``).
TAIL = 100


@dataclass(frozen=True)
class ServiceLog:
    """A service's log stream through the manager, with the ``logs(stream=, follow=, tail=)`` of a docker-py
    container, so :func:`robocore.commands.logs.follow_logs` merges it as it merges containers."""

    client: docker.DockerClient
    service: str

    def logs(self, *, stream: bool = True, follow: bool = False, tail: int = TAIL) -> Iterator[bytes]:
        """The service's output, chunk by chunk."""
        del stream  # always a stream: the manager sends it so
        return swarm_tasks.log_chunks(self.client, self.service, follow=follow, tail=tail)


def logs(options: Options, *, robot: str, component: str | None, follow: bool) -> list[Part]:
    """Print the logs of ``robot``'s services (or of ``component``'s) through the manager (see the module); the
    parts read are returned."""
    fleet = load(options)
    parts = robot_parts(fleet.name, fleet.instances, robot, component)
    if options.dry_run:
        options.report.plain(manager_line(fleet))
        for part in parts:
            options.report.plain(f"would read {'and follow ' if follow else ''}the logs of service {part.service} "
                                 f"({robot}'s {part.name} on its host {part.host}) through the manager")
        return parts
    client = _client(fleet)
    try:
        away = set(offline(robot, robot_nodes(swarm.nodes(client), fleet), fleet))
        readable = [p for p in parts if p.host not in away]
        for part in parts:
            if part.host in away:
                options.report.notice(f"{robot}: host {part.host} is offline (its swarm node is not ready): the "
                                      f"manager cannot read {part.name}'s logs until it is back", style="red")
        width = max((len(p.name) for p in readable), default=0)
        if follow:
            follow_logs(options.report, [(p.host, p.name, ServiceLog(client, p.service)) for p in readable], width,
                        TAIL)
        else:
            for part in readable:
                for line in split_lines(ServiceLog(client, part.service).logs(tail=TAIL)):
                    emit_line(options.report, LogLine(part.name, part.host, line), width, stream=False)
    finally:
        client.close()
    if not readable:
        raise HostError(f"robot {robot} is offline: no logs of it can be read through the manager")
    return parts


def _client(fleet: FleetProject) -> docker.DockerClient:
    """A client of the manager whose reads may wait as long as a quiet component may be silent."""
    from robocore.adapters.docker_hosts import client_for

    assert fleet.fleet.manager is not None
    return client_for(fleet.fleet.manager.as_host(), LOG_STREAM_TIMEOUT, project_root=fleet.project.root)
