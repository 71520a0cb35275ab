"""A robot brought up for tests on one Docker daemon, as data.

A test run starts the project's own images with the project's own discovery configuration,
but isolated from the robot and from other runs: every robot host becomes one network
namespace (a small "host" container on the run's private network, whose network and IPC
the host's components and discovery servers join, as host networking and ``ipc: host`` give
on the robot), the hosts' addresses become those containers' addresses, and the run has its
own ROS domain. Everything the run creates carries :data:`LABEL_RUN` and :data:`LABEL_OWNER`,
so that the next run can remove what a killed one left behind.

Pure functions: the Docker work is in :mod:`robocore.testing.bringup`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

from robocore.config.model import DockerAccess, Robot
from robocore.plan import containers, discovery, naming
from robocore.plan.containers import ContainerSpec
from robocore.project import Project

LABEL_RUN = "dev.robocore.testrun"
#: ``<hostname>|<boot id>|<pid>|<process start ticks>`` of the pytest process that owns the run.
LABEL_OWNER = "dev.robocore.testrun.owner"
ROLE_HOST = "testhost"
#: The command of a host container: hold the namespaces, nothing else.
HOST_COMMAND = ("sleep", "infinity")


@dataclass(frozen=True)
class TestRun:
    """The identity of one test run of one project."""

    __test__ = False  # not a pytest test class

    project: str  # the project's name (folder slug)
    run_id: str  # short random hex
    domain_id: int
    owner: str  # LABEL_OWNER value

    @property
    def prefix(self) -> str:
        """The prefix of every container, network and volume name of the run."""
        return f"{self.project}-t{self.run_id}"

    @property
    def network(self) -> str:
        """The run's private network, which the host containers join."""
        return f"{self.prefix}-net"

    @property
    def labels(self) -> dict[str, str]:
        """Labels of everything the run creates."""
        return {LABEL_RUN: self.run_id, LABEL_OWNER: self.owner}

    @property
    def label_project(self) -> str:
        """The project label of the run's containers: never the robot's own, so ``down`` and ``status`` skip them."""
        return f"{self.project}-test-{self.run_id}"

    def host_container(self, host: str) -> str:
        """The container that is robot host ``host`` for this run."""
        return f"{self.prefix}-host-{host}"

    def component_container(self, component: str) -> str:
        """The container of ``component`` in this run."""
        return f"{self.prefix}-{component}"

    def server_container(self, index: int) -> str:
        """The container of discovery server ``index`` in this run."""
        return f"{self.prefix}-discovery-{index}"

    def fault_agent(self, host: str) -> str:
        """The fault agent of robot host ``host`` (:mod:`robocore.plan.faults`): nft and tc in its namespace."""
        return f"{self.prefix}-faults-{host}"

    def server_volume(self, index: int) -> str:
        """The state volume of discovery server ``index`` in this run (a restart within the run holds, as deployed)."""
        return f"{self.prefix}-discovery-{index}-state"


def hosts_to_start(robot: Robot) -> list[str]:
    """Robot hosts that run a component or a discovery server, in file order."""
    return [h.name for h in robot.hosts_in_use()]


def isolated_robot(robot: Robot, addresses: Mapping[str, str], domain_id: int) -> Robot:
    """``robot`` with each started host at its run address, reached through the local daemon, in ``domain_id``."""
    hosts = [
        h.model_copy(update={"ip": addresses[h.name], "docker": DockerAccess.local}) if h.name in addresses else h
        for h in robot.hosts
    ]
    return robot.model_copy(update={"hosts": hosts, "ros_domain_id": domain_id})


def probe_discovery(robot: Robot) -> discovery.Discovery:
    """The robot's discovery as the test process sees it: UDP only (it cannot share the containers' memory)."""
    return discovery.for_robot(robot, discovery.UDP)


def probe_environment(robot: Robot, profile_path: str) -> dict[str, str]:
    """Environment of the test process's observer node; its profile (:func:`probe_profile`) is the file at
    ``profile_path``."""
    return probe_discovery(robot).observer_environment(files=lambda _name: profile_path)


def probe_profile(robot: Robot) -> str:
    """The one file the test process's observer node reads (empty when the discovery kind gives observers none).

    It names no server: a test session may bring up several robots, one after the other, and Fast DDS reads
    a process's profile file only at its first participant; the environment (:func:`probe_environment`),
    which it reads for each participant, says which servers, and that the node is a super client."""
    kind = probe_discovery(robot)
    return kind.files()[kind.probe_file] if kind.probe_file else ""


def host_spec(run: TestRun, project: Project, host: str) -> ContainerSpec:
    """The container that holds robot host ``host``'s network and IPC namespaces (the base image of its arch, as
    its discovery servers run: the one base a robot of no host of this machine's arch has of it)."""
    return ContainerSpec(
        name=run.host_container(host),
        service=f"host-{host}",
        host=host,
        role=ROLE_HOST,
        project=run.label_project,
        image=containers.base_ref(project, project.robot.host(host).arch.value, None),
        entrypoint=HOST_COMMAND[:1],
        command=HOST_COMMAND[1:],
        environment=(),
        network_mode=run.network,
        ipc_mode="shareable",
        restart="no",
        extra_labels=tuple(sorted(run.labels.items())),
    )


def _in_host(run: TestRun, spec: ContainerSpec, *, name: str, dds_dir: str, share_ipc: bool) -> ContainerSpec:
    """``spec`` moved into its host container's namespaces, with the run's name, labels and DDS profiles."""
    namespace = f"container:{run.host_container(spec.host)}"
    mounts = tuple(
        dataclasses.replace(m, source=dds_dir) if m.target == naming.CONTAINER_DDS else m for m in spec.mounts
    )
    return dataclasses.replace(
        spec,
        name=name,
        project=run.label_project,
        network_mode=namespace,
        ipc_mode=namespace if share_ipc else None,
        ports=(),
        mounts=mounts,
        restart="no",
        depends_on=(),
        extra_labels=(*spec.extra_labels, *sorted(run.labels.items())),
    )


def component_specs(run: TestRun, project: Project, dds_dir: str) -> dict[str, ContainerSpec]:
    """Component name -> its container in the run (``project`` is the isolated one)."""
    share = discovery.Transport.of(project.robot).shared_memory
    out = {}
    for component in project.robot.components:
        spec = containers.component_spec(project, component)
        out[component.name] = _in_host(run, spec, name=run.component_container(component.name), dds_dir=dds_dir,
                                       share_ipc=share)
    return out


def server_specs(run: TestRun, project: Project, dds_dir: str) -> list[ContainerSpec]:
    """The run's discovery servers, in id order, each with its own state volume."""
    share = discovery.Transport.of(project.robot).shared_memory
    out = []
    for server in discovery.for_robot(project.robot).servers():
        spec = containers.discovery_spec(project, server.index)
        mounts = tuple(dataclasses.replace(m, source=run.server_volume(server.index)) if m.is_named_volume else m
                       for m in spec.mounts)
        spec = dataclasses.replace(spec, mounts=mounts)
        out.append(_in_host(run, spec, name=run.server_container(server.index), dds_dir=dds_dir, share_ipc=share))
    return out


def boot_services(project: Project) -> dict[str, tuple[str, str, str]]:
    """Service -> (its host, its role, its restart policy on the robot): what a host's boot starts
    (:func:`robocore.plan.faults.boot_order`). The run's containers themselves never restart on their own."""
    out = {}
    for server in discovery.for_robot(project.robot).servers():
        spec = containers.discovery_spec(project, server.index)
        out[spec.service] = (spec.host, spec.role, spec.restart)
    for component in project.robot.components:
        out[component.name] = (component.runs_on, naming.ROLE_COMPONENT, component.restart)
    return out
