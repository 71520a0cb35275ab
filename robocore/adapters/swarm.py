"""Docker Swarm through docker-py: the one place robocore talks to a swarm (manager and joining nodes).

Thin wrappers: the swarm's state in and out as plain data, :class:`~robocore.plan.swarm_services.ServiceSpec`
turned into docker-py arguments, docker-py's errors turned into :class:`~robocore.errors.DockerError` naming
what failed. Clients come from :mod:`robocore.adapters.docker_hosts` (ssh, TLS, local), as for robot hosts.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from robocore.errors import DockerError
from robocore.plan.registry_trust import pull_hint
from robocore.plan.resources import swarm_resources
from robocore.plan.swarm_services import ConfigFile, ServiceSpec

if TYPE_CHECKING:
    import docker

#: Port of the swarm's manager API (Docker's default).
SWARM_PORT = 2377
#: Nanoseconds a task has to stop before it is killed (Docker's default, given explicitly: see service_kwargs).
STOP_GRACE_NS = 10_000_000_000
#: Swarm task states after which a task never runs again.
ENDED = frozenset({"complete", "failed", "shutdown", "rejected", "orphaned", "remove"})


@contextmanager
def swarm_errors(what: str) -> Iterator[None]:
    """Turn docker-py's API errors during ``what`` into a DockerError that says what failed."""
    from docker.errors import APIError

    try:
        yield
    except APIError as exc:
        text = str(getattr(exc, "explanation", None) or exc).strip().splitlines()
        raise DockerError(f"{what}: {text[0] if text else type(exc).__name__}") from None


@dataclass(frozen=True)
class SwarmState:
    """A daemon's view of swarm membership (``docker info``'s Swarm part)."""

    state: str  # inactive | pending | active | error | locked
    node_id: str
    cluster_id: str
    is_manager: bool


def swarm_state(client: docker.DockerClient) -> SwarmState:
    """Whether the daemon of ``client`` is in a swarm, which node it is and of which cluster."""
    with swarm_errors("docker info"):
        info = client.info().get("Swarm") or {}
    cluster = info.get("Cluster") or {}
    return SwarmState(state=str(info.get("LocalNodeState") or "inactive"), node_id=str(info.get("NodeID") or ""),
                      cluster_id=str(cluster.get("ID") or ""), is_manager=bool(info.get("ControlAvailable")))


def init_swarm(client: docker.DockerClient, advertise: str) -> None:
    """Make the daemon of ``client`` the first manager of a new swarm, advertised at ``advertise``."""
    with swarm_errors(f"docker swarm init --advertise-addr {advertise}"):
        client.swarm.init(advertise_addr=advertise, listen_addr=f"0.0.0.0:{SWARM_PORT}")


def worker_token(client: docker.DockerClient) -> str:
    """The swarm's worker join token (read from the manager)."""
    with swarm_errors("reading the swarm's join token"):
        client.swarm.reload()
        return str(client.swarm.attrs["JoinTokens"]["Worker"])


def join_swarm(client: docker.DockerClient, manager: str, token: str, advertise: str) -> None:
    """Join the daemon of ``client`` to the swarm whose manager is at ``manager`` as a worker."""
    with swarm_errors(f"docker swarm join {manager}"):
        client.swarm.join(remote_addrs=[f"{manager}:{SWARM_PORT}"], join_token=token, advertise_addr=advertise,
                          listen_addr=f"0.0.0.0:{SWARM_PORT}")


@dataclass(frozen=True)
class NodeInfo:
    """One node of the swarm as the manager sees it."""

    id: str
    hostname: str
    labels: dict[str, str]
    state: str  # ready | down | unknown | disconnected
    availability: str  # active | pause | drain
    addr: str


def nodes(client: docker.DockerClient) -> list[NodeInfo]:
    """Every node of the swarm."""
    with swarm_errors("docker node ls"):
        found = client.nodes.list()
    return [_node(n.attrs) for n in found]


def _node(attrs: dict[str, Any]) -> NodeInfo:
    spec = attrs.get("Spec") or {}
    status = attrs.get("Status") or {}
    return NodeInfo(id=str(attrs.get("ID")), hostname=str((attrs.get("Description") or {}).get("Hostname") or ""),
                    labels=dict(spec.get("Labels") or {}), state=str(status.get("State") or "unknown"),
                    availability=str(spec.get("Availability") or "active"), addr=str(status.get("Addr") or ""))


def update_node(client: docker.DockerClient, node_id: str, *, labels: dict[str, str] | None = None,
                availability: str | None = None) -> None:
    """Set a node's labels (all of them) and/or availability."""
    with swarm_errors(f"docker node update {node_id}"):
        node = client.nodes.get(node_id)
        spec = dict(node.attrs["Spec"])
        if labels is not None:
            spec["Labels"] = labels
        if availability is not None:
            spec["Availability"] = availability
        node.update(spec)


def ensure_configs(client: docker.DockerClient, files: tuple[ConfigFile, ...]) -> dict[str, str]:
    """Create the Swarm configs of ``files`` that do not exist yet (they are immutable and named by content);
    return config name -> id."""
    from docker.errors import APIError, NotFound

    ids: dict[str, str] = {}
    for file in files:
        if file.name in ids:
            continue
        with swarm_errors(f"docker config create {file.name}"):
            try:
                ids[file.name] = str(client.configs.get(file.name).id)
            except NotFound:
                try:
                    ids[file.name] = str(client.configs.create(name=file.name, data=file.text.encode()).id)
                except APIError as exc:  # made meanwhile by another run
                    if getattr(exc, "status_code", None) != 409:
                        raise
                    ids[file.name] = str(client.configs.get(file.name).id)
    return ids


def service_kwargs(spec: ServiceSpec, config_ids: dict[str, str]) -> dict[str, Any]:
    """docker-py ``services.create``/``update`` keyword arguments of ``spec``."""
    from docker.types import ConfigReference, DNSConfig, Mount, Resources, RestartPolicy, ServiceMode, UpdateConfig

    mounts = [Mount(m.target, m.source, type="volume" if m.is_named_volume else "bind", read_only=m.read_only)
              for m in spec.mounts]
    configs = [ConfigReference(config_ids[c.name], c.name, filename=c.target, mode=0o444) for c in spec.configs]
    return {
        "image": spec.image,
        "name": spec.name,
        "command": list(spec.command) if spec.command is not None else None,
        "args": list(spec.args) if spec.args is not None else None,
        "env": [f"{key}={value}" for key, value in spec.environment],
        "mounts": mounts,
        "configs": configs,
        "networks": ["host"],
        "constraints": list(spec.constraints),
        "restart_policy": RestartPolicy(condition=spec.restart, delay=int(1e9)),  # type: ignore[arg-type]
        # stop-first: never two copies of one ROS node; robocore rolls whole robots back itself
        "update_config": UpdateConfig(parallelism=1, order="stop-first", failure_action="continue", monitor=int(1e9)),
        "labels": spec.label_map,
        # global, pinned to one node: at most one task, on that node only; a node that is down keeps its task
        # (no replacement waits elsewhere, which Swarm's scheduler may leave pending after the node is back) and
        # gets the service's current spec when it returns. A one-shot probe is one replica.
        "mode": ServiceMode("replicated", 1) if spec.restart == "none" else ServiceMode("global"),
        # an init as PID 1 for every task: it passes SIGTERM on, so a process with no handler of its own (the
        # discovery server) stops at once instead of being killed after the grace period
        "init": True,
        # what the daemon fills in on an update when absent: given from the start, the first update of an
        # unchanged service replaces no task
        "stop_grace_period": STOP_GRACE_NS,
        "resources": Resources(**swarm_resources(spec.limits)),
        "dns_config": DNSConfig(),
    }


@dataclass(frozen=True)
class TaskInfo:
    """One task of a service."""

    id: str
    node_id: str
    state: str
    desired: str
    image: str
    created: str
    error: str
    exit_code: int | None
    container: str  # the task's container id ("" until one was made)

    @property
    def hint(self) -> str:
        """What to do when the task's error is a pull that failed (:func:`pull_hint`); "" otherwise."""
        return pull_hint(self.image, self.error)

    @property
    def why(self) -> str:
        """The task's error, with :attr:`hint` when it has one."""
        return f"{self.error} ({self.hint})" if self.hint else self.error


@dataclass(frozen=True)
class ServiceInfo:
    """One service as the manager holds it: its labels, image, and version (for updates)."""

    id: str
    name: str
    labels: dict[str, str]
    image: str
    version: int
    attrs: dict[str, Any]


def services(client: docker.DockerClient, label: str) -> list[ServiceInfo]:
    """The services carrying ``label`` (``key=value``)."""
    with swarm_errors("docker service ls"):
        found = client.services.list(filters={"label": label})
    return [_service(s.attrs) for s in found]


def _service(attrs: dict[str, Any]) -> ServiceInfo:
    spec = attrs.get("Spec") or {}
    container = ((spec.get("TaskTemplate") or {}).get("ContainerSpec")) or {}
    return ServiceInfo(id=str(attrs.get("ID")), name=str(spec.get("Name")), labels=dict(spec.get("Labels") or {}),
                       image=str(container.get("Image") or ""), version=int((attrs.get("Version") or {}).get("Index")
                                                                            or 0), attrs=attrs)


#: Service label: a digest of everything robocore sends of a service but its labels (its tasks' template, mode and
#: update order). An update whose digest equals the stored one changes labels only, so Swarm replaces no task: a
#: service a release does not change (a discovery server, a component of the same image) keeps its container.
LABEL_TEMPLATE = "dev.robocore.fleet.template"


def template_digest(kwargs: dict[str, Any]) -> str:
    """The digest of ``service_kwargs``' output without its labels (docker-py's types are dicts: JSON as sent)."""
    import hashlib
    import json

    sent = {key: value for key, value in kwargs.items() if key != "labels"}
    return hashlib.sha256(json.dumps(sent, sort_keys=True, default=str).encode()).hexdigest()[:16]


def apply_service(client: docker.DockerClient, spec: ServiceSpec, config_ids: dict[str, str]) -> str:
    """Create ``spec``'s service, or update it in place when it exists (stop-first); return the service id.

    An existing service whose stored template digest (:data:`LABEL_TEMPLATE`) is the wanted one gets its labels
    only, with the rest of its stored spec sent back as it is: no task of it is replaced. A one-shot service
    (restart condition ``none``, such as a probe) is only ever created: its one task is its result."""
    from docker.errors import NotFound

    kwargs = service_kwargs(spec, config_ids)
    digest = template_digest(kwargs)
    kwargs["labels"] = {**kwargs["labels"], LABEL_TEMPLATE: digest}
    with swarm_errors(f"docker service update {spec.name}"):
        try:
            service = client.services.get(spec.name)  # type: ignore[no-untyped-call]
            if mode_of(service.attrs) != mode_of({"Spec": {"Mode": kwargs["mode"]}}):
                remove_stopped(client, [spec.name])  # Swarm never changes a service's mode: made anew, stop-first
                raise NotFound(spec.name)
        except NotFound:
            service = client.services.create(**kwargs)  # type: ignore[no-untyped-call]
            if spec.restart == "none":
                return str(service.id)
            # The daemon fills defaults into a service's first update (an empty Resources), which would make the
            # first update of an unchanged service replace its task: that update is made now, at creation.
            service.reload()
            unchanged = False
        else:
            unchanged = ((service.attrs.get("Spec") or {}).get("Labels") or {}).get(LABEL_TEMPLATE) == digest
        name = kwargs.pop("name")

        def update() -> None:
            if unchanged:
                _send_labels(client, service.attrs, kwargs["labels"])
            else:
                service.update(name=name, **kwargs)

        in_sequence(update, reread=service.reload)
        return str(service.id)


def mode_of(attrs: dict[str, Any]) -> set[str]:
    """A service's mode (``global`` or ``replicated``) from its inspected ``attrs``. The daemon stores the mode
    under Go's field names (``Global``) while docker-py sends ``global``: compared as they are, every service would
    look changed in mode and be removed and made anew on each update, its old task still stopping beside the new
    one (two copies of one node, two discovery servers on one port)."""
    return {str(key).lower() for key in ((attrs.get("Spec") or {}).get("Mode") or {})}


def _send_labels(client: docker.DockerClient, attrs: dict[str, Any], labels: dict[str, str]) -> None:
    """Update the service of ``attrs`` (as inspected, without defaults filled in) to ``labels``, every other part
    of its spec sent back exactly as stored: its task template does not change, so no task is replaced."""
    spec = attrs.get("Spec") or {}
    client.api.update_service(
        attrs["ID"], attrs["Version"]["Index"], task_template=spec.get("TaskTemplate"), name=spec.get("Name"),
        labels=labels, mode=spec.get("Mode"), update_config=spec.get("UpdateConfig"),
        rollback_config=spec.get("RollbackConfig"), endpoint_spec=spec.get("EndpointSpec"))


#: How many times an update refused as "out of sequence" is tried again on the service's new version.
UPDATE_ATTEMPTS = 5


def out_of_sequence(exc: Exception) -> bool:
    """Whether Swarm refused an update because the service changed since it was read (its version index moved:
    the manager itself bumps it, e.g. while it reconciles a node that came back). The update is then made again
    on the new version; any other refusal is an error."""
    return "update out of sequence" in str(getattr(exc, "explanation", None) or exc)


def in_sequence(update: Callable[[], None], *, reread: Callable[[], object] | None = None) -> None:
    """``update()``, made again when the manager refuses it as out of sequence (:func:`out_of_sequence`), after
    ``reread()`` of the service it changes, up to :data:`UPDATE_ATTEMPTS` times in all; any other refusal, or the
    last one, is raised."""
    from docker.errors import APIError

    for attempt in range(1, UPDATE_ATTEMPTS + 1):
        try:
            update()
            return
        except APIError as exc:
            if attempt == UPDATE_ATTEMPTS or not out_of_sequence(exc):
                raise
            if reread is not None:
                reread()


def updating(client: docker.DockerClient, name: str) -> bool:
    """True while Swarm is still rolling ``name``'s last update out (its UpdateStatus is ``updating``)."""
    from docker.errors import NotFound

    with swarm_errors(f"docker service inspect {name}"):
        try:
            attrs = client.api.inspect_service(name)  # type: ignore[no-untyped-call]
        except NotFound:
            return False
    return str((attrs.get("UpdateStatus") or {}).get("State") or "") in ("updating", "rollback_started")


def set_labels(client: docker.DockerClient, name: str, labels: dict[str, str]) -> None:
    """Set ``name``'s service labels only: the stored spec is sent back as it is, so no task changes."""
    def update() -> None:  # reads the service each time: a retry updates its new version
        attrs = client.api.inspect_service(name)  # type: ignore[no-untyped-call]
        _send_labels(client, attrs, {**((attrs.get("Spec") or {}).get("Labels") or {}), **labels})

    with swarm_errors(f"docker service update --label-add {name}"):
        in_sequence(update)


def remove_service(client: docker.DockerClient, name: str) -> None:
    """Remove a service (nothing when it is gone)."""
    from docker.errors import NotFound

    with swarm_errors(f"docker service rm {name}"):
        try:
            client.services.get(name).remove()  # type: ignore[no-untyped-call]
        except NotFound:
            return


#: Seconds :func:`remove_stopped` waits for a removed service's containers to stop: their stop grace period, and
#: a few seconds for the robot's daemon to report it to the manager.
STOPPED_WAIT = STOP_GRACE_NS / 1e9 + 10


def remove_stopped(client: docker.DockerClient, names: list[str], timeout: float = STOPPED_WAIT) -> list[str]:
    """Remove the services ``names`` and wait until every task of theirs that ran has stopped (its container
    stopped, as its node's daemon reported), at most ``timeout`` seconds; return the ids of the tasks still not
    stopped then. Swarm removes a service at once and stops its containers afterwards: a service made anew under the
    same name without this wait starts its container beside the old one (two copies of one ROS node, measured at
    0.7 s on a canary's way back). A task on a node that is not ready is not waited for: nothing can report it,
    and its node stops it when it is back, before it takes the new spec."""
    ready = {n.id for n in nodes(client) if n.state == "ready"}
    live = [t.id for name in names for t in tasks(client, name)
            if t.state not in ENDED and t.node_id in ready]
    for name in names:
        remove_service(client, name)
    end = time.monotonic() + timeout
    while live:
        with swarm_errors("docker service ps"):
            found = [_task(t) for t in client.api.tasks(filters={"id": live})]  # type: ignore[no-untyped-call]
        live = [t.id for t in found if t.id in live and t.state not in ENDED]
        if not live or time.monotonic() >= end:
            break
        time.sleep(0.2)
    return live


def tasks(client: docker.DockerClient, service: str) -> list[TaskInfo]:
    """The tasks of ``service`` (by name), newest first."""
    from docker.errors import NotFound

    with swarm_errors(f"docker service ps {service}"):
        try:
            found = client.api.tasks(filters={"service": service})  # type: ignore[no-untyped-call]
        except NotFound:
            return []
    out = [_task(t) for t in found]
    return sorted(out, key=lambda t: t.created, reverse=True)


def _task(attrs: dict[str, Any]) -> TaskInfo:
    status = attrs.get("Status") or {}
    container = (((attrs.get("Spec") or {}).get("ContainerSpec")) or {})
    code = (status.get("ContainerStatus") or {}).get("ExitCode")
    return TaskInfo(id=str(attrs.get("ID")), node_id=str(attrs.get("NodeID") or ""), state=str(status.get("State")),
                    desired=str(attrs.get("DesiredState")), image=str(container.get("Image") or ""),
                    created=str(attrs.get("CreatedAt") or ""), error=str(status.get("Err") or ""),
                    exit_code=int(code) if isinstance(code, int) else None,
                    container=str((status.get("ContainerStatus") or {}).get("ContainerID") or ""))


def service_logs(client: docker.DockerClient, service: str) -> str:
    """What ``service``'s tasks printed (stdout and stderr), read through the manager."""
    with swarm_errors(f"docker service logs {service}"):
        chunks = client.api.service_logs(service, stdout=True, stderr=True, follow=False)
        return b"".join(chunks).decode(errors="replace")
