"""``fleet join``: make (or reuse) the swarm on the manager, join every host of every robot, label the nodes.

Idempotent: a host already in this swarm is not joined again, a node whose labels are right is not touched. A
robot added to the fleet file joins; the nodes of a robot no longer in it are drained (their tasks stop) and its
services removed. Each node gets robocore's labels (project, robot, host, arch), on which every service is pinned.
A host that cannot be reached is reported by name; the others are still joined.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from robocore.adapters import swarm
from robocore.commands.fleet_swarm import FleetProject, load, manager_client, manager_line, project_label
from robocore.commands.support.context import Options
from robocore.commands.support.hosts import in_parallel, short_error
from robocore.commands.support.registry_ca import Trust
from robocore.config.model import Host
from robocore.errors import GroupError, HostError, RobocoreError
from robocore.plan import swarm_services as plan

#: Hosts joined at once.
JOIN_PARALLEL = 8


@dataclass(frozen=True)
class JoinResult:
    """What ``fleet join`` did to one robot host."""

    kind: ClassVar[str] = "fleet_join"
    robot: str
    host: str
    node: str
    action: str  # joined | labelled | unchanged | drained


def _join_host(host: Host, *, manager_ip: str, token: str, cluster: str, trust: Trust | None = None) -> str:
    """Join ``host``'s daemon to the swarm (unless it already is in it), the registry's CA installed on it first
    when ``trust`` gives one; return its node id."""
    from robocore.adapters.docker_hosts import client_for

    client = client_for(host, 120)
    try:
        if trust is not None:
            trust.install(client, host)
        state = swarm.swarm_state(client)
        if state.state == "active" and state.cluster_id and state.cluster_id != cluster:
            raise HostError(f"{host.ip} is already in another swarm (cluster {state.cluster_id[:12]})",
                            hint=f"leave it first: ssh {host.user}@{host.ip} docker swarm leave")
        if state.state == "active" and state.node_id:
            return "=" + state.node_id
        swarm.join_swarm(client, manager_ip, token, host.ip)
        return swarm.swarm_state(client).node_id
    finally:
        client.close()


def join(options: Options) -> list[JoinResult]:
    """Join every host of every robot of the fleet to the manager's swarm and label the nodes (see the module)."""
    fleet = load(options)
    report = options.report
    assert fleet.fleet.manager is not None
    manager = fleet.fleet.manager
    targets = [(robot, host) for robot, instance in fleet.instances.items() for host in instance.hosts]
    trust = Trust.of(fleet)
    if options.dry_run:
        report.plain(f"swarm manager {manager.ip}: init unless it is one")
        report.plain(manager_line(fleet))
        from robocore.adapters.docker_hosts import describe

        for robot, host in targets:
            report.plain(f"join {robot}/{host.name} ({host.ip}, docker via {describe(host)}) and label it "
                         f"{plan.NODE_ROBOT}={robot} {plan.NODE_HOST}={host.name} {plan.NODE_ARCH}={host.arch.value}"
                         + (f"; {trust.dry_run()}" if trust else ""))
        return []
    client = manager_client(fleet)
    try:
        state = swarm.swarm_state(client)
        if state.state != "active":
            report.info(f"making a swarm on {manager.ip}")
            swarm.init_swarm(client, manager.ip)
            state = swarm.swarm_state(client)
        elif not state.is_manager:
            raise HostError(f"the manager {manager.ip} is a worker of another swarm, not a manager")
        token = swarm.worker_token(client)
        outcomes = in_parallel(targets, lambda item: _join_host(item[1], manager_ip=manager.ip, token=token,
                                                                 cluster=state.cluster_id, trust=trust),
                               limit=JOIN_PARALLEL, name="robocore-join")
        results, failures = _label(client, fleet, outcomes)
        results += _drain_removed(client, fleet)
    finally:
        client.close()
    for result in results:
        report.info(f"{result.robot}/{result.host}: {result.action}")
    report.add(*results)
    if failures:
        raise GroupError(failures, [f"{r.robot}/{r.host}" for r in results])
    return results


def _label(client: object, fleet: FleetProject,
           outcomes: list[tuple[tuple[str, Host], str | BaseException]]) -> tuple[list[JoinResult],
                                                                                 dict[str, RobocoreError]]:
    import docker

    assert isinstance(client, docker.DockerClient)
    results: list[JoinResult] = []
    failures: dict[str, RobocoreError] = {}
    nodes = {n.id: n for n in swarm.nodes(client)}
    for (robot, host), outcome in outcomes:
        key = f"{robot}/{host.name}"
        if isinstance(outcome, RobocoreError):
            failures[key] = outcome
            continue
        if isinstance(outcome, BaseException):
            if not isinstance(outcome, Exception):
                raise outcome
            failures[key] = HostError(f"{host.ip}: {short_error(outcome)}")
            continue
        already = outcome.startswith("=")
        node_id = outcome.lstrip("=")
        wanted = plan.node_labels(fleet.name, robot, host.name, host.arch.value)
        node = nodes.get(node_id)
        if node is None:
            nodes = {n.id: n for n in swarm.nodes(client)}
            node = nodes.get(node_id)
        if node is None:
            failures[key] = HostError(f"{host.ip} joined, but the manager does not list its node {node_id[:12]}")
            continue
        labels = {**node.labels, **wanted}
        if labels != node.labels or node.availability != "active":
            swarm.update_node(client, node_id, labels=labels, availability="active")
            action = "labelled" if already else "joined"
        else:
            action = "unchanged" if already else "joined"
        results.append(JoinResult(robot=robot, host=host.name, node=node_id[:12], action=action))
    return results, failures


def _drain_removed(client: object, fleet: FleetProject) -> list[JoinResult]:
    """Drain the nodes of robots no longer in the fleet file and remove their services."""
    import docker

    assert isinstance(client, docker.DockerClient)
    results = []
    gone: set[str] = set()
    for node in swarm.nodes(client):
        robot = node.labels.get(plan.NODE_ROBOT)
        if node.labels.get(plan.NODE_PROJECT) != fleet.name or robot is None or robot in fleet.instances:
            continue
        gone.add(robot)
        if node.availability != "drain":
            swarm.update_node(client, node.id, availability="drain")
            results.append(JoinResult(robot=robot, host=node.labels.get(plan.NODE_HOST, "?"), node=node.id[:12],
                                      action="drained"))
    for service in swarm.services(client, project_label(fleet)):
        if service.labels.get(plan.LABEL_ROBOT) in gone:
            swarm.remove_service(client, service.name)
    return results
