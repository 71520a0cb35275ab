"""``robot.faults``: cut a robot host off, partition the hosts, limit a host's link, power-cut a host.

The plans are :mod:`robocore.plan.faults`; this module applies them on the local Docker daemon.
Each robot host of a run is one network namespace (:mod:`robocore.plan.testrun`). A fault reaches
it through that host's *fault agent*: a container started on the first fault of the host, in the
host's network namespace, with ``NET_ADMIN`` and nothing else, from an image made of the robot's
base image plus Debian's ``nftables`` and ``iproute2`` (built once per base image). The dev
machine needs no root, and no rule leaves the run's own namespaces.

Every fault is undone before the next test, also when the test fails (the plugin calls
:meth:`Faults.clear`), and a failed test's report lists the faults in force (:meth:`Faults.describe`).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from robocore.errors import RobocoreError
from robocore.plan import faults as plan
from robocore.plan import naming, testrun
from robocore.plan.dockerfiles import ImagePlan
from robocore.plan.testrun import TestRun
from robocore.project import Project

#: The fault agent image: ``robocore-faults:<first 12 hex digits of the base image's ID>``.
AGENT_IMAGE = "robocore-faults"


class FaultError(RobocoreError):
    """A fault could not be applied or undone (the agent's command failed, or the kernel lacks a feature)."""

    exit_code = 1


class Faults:
    """The faults of one run: what is in force, and the agents that apply it."""

    def __init__(self, client: Any, run: TestRun, project: Project, services: Callable[[], dict[str, Any]],
                 container: Callable[[str], Any]) -> None:
        self._client = client
        self._run = run
        self._project = project
        self._services = services  # service -> its ContainerSpec
        self._container = container  # service -> its docker-py container
        self.active: list[plan.Fault] = []
        self._agents: dict[str, Any] = {}
        self._filters: dict[str, plan.HostFilter] = {}
        self._shaped: set[str] = set()
        self._netem: bool | None = None
        self._observer: str | None = None

    # ------------------------------------------------------------------ the faults

    @property
    def hosts(self) -> list[str]:
        """The run's robot hosts (those that run something), in robot.yaml order."""
        return testrun.hosts_to_start(self._project.robot)

    def host_of(self, service: str) -> str:
        """The robot host that runs ``service`` (a component, or ``discovery-N``)."""
        try:
            return str(self._services()[service].host)
        except KeyError:
            raise FaultError(f"no component {service!r} in this run (known: {', '.join(self._services())})") from None

    def cut_off(self, host: str) -> None:
        """Take ``host`` off the network: nothing in or out (other hosts, the test process), loopback excepted."""
        self._add(plan.CutOff(plan.check_host(host, self.hosts)))

    def reconnect(self, host: str) -> None:
        """Undo :meth:`cut_off` of ``host``."""
        self._remove(lambda f: isinstance(f, plan.CutOff) and f.host == host)

    def partition(self, *groups: Iterable[str]) -> None:
        """Split the hosts into ``groups`` that cannot reach each other (every host in one group; the test
        process stays with the first group). Replaces an earlier partition."""
        fault = plan.partition(groups, self.hosts)
        self.active = [f for f in self.active if not isinstance(f, plan.Partition)]
        self._add(fault)

    def heal(self) -> None:
        """Undo the partition and every cut-off: the network is whole again (link limits stay)."""
        self._remove(lambda f: isinstance(f, plan.Partition | plan.CutOff))

    def limit_link(self, host: str, rate_kbit: int | None = None, *, loss_percent: float = 0.0,
                   delay_ms: int = 0) -> None:
        """Limit ``host``'s link each way to ``rate_kbit`` kbit/s (tc tbf), drop ``loss_percent`` % of its
        packets at random (nftables), delay them by ``delay_ms`` (needs the kernel's netem: FaultError
        with :data:`~robocore.plan.faults.DELAY_UNAVAILABLE` when it is missing)."""
        fault = plan.link_limit(plan.check_host(host, self.hosts), rate_kbit=rate_kbit, loss_percent=loss_percent,
                                delay_ms=delay_ms)
        if fault.delay_ms and not self._has_netem(host):
            raise FaultError(plan.DELAY_UNAVAILABLE)
        self.unlimit_link(host)
        if fault.rate_kbit or fault.delay_ms:
            self._exec(host, plan.shape_argv(fault.rate_kbit, fault.delay_ms))
            self._shaped.add(host)
        self._add(fault)

    def unlimit_link(self, host: str) -> None:
        """Undo :meth:`limit_link` of ``host``."""
        if host in self._shaped:
            self._exec(host, plan.unshape_argv())
            self._shaped.discard(host)
        self._remove(lambda f: isinstance(f, plan.LinkLimit) and f.host == host)

    def power_cut(self, host: str) -> list[str]:
        """SIGKILL every process of ``host`` at once and take it off the network; return the services killed.

        The host stays off until :meth:`boot` (or the next test)."""
        plan.check_host(host, self.hosts)
        self.active.append(plan.PowerCut(host))
        victims = [s for s, spec in self._services().items() if spec.host == host and self._running(s)]
        with ThreadPoolExecutor(max_workers=len(victims) + 1) as pool:
            jobs = [pool.submit(self._refilter)]
            jobs += [pool.submit(self._container(s).kill, "SIGKILL") for s in victims]
            for job in jobs:
                job.result()
        return victims

    def boot(self, host: str) -> list[str]:
        """Boot ``host`` after :meth:`power_cut`: /dev/shm emptied (as a tmpfs after a power loss), back on the
        network, its containers started as the robot's restart policy starts them (servers first); return them."""
        if plan.PowerCut(host) not in self.active:
            raise FaultError(f"host {host} is not powered off")
        self._client.containers.get(self._run.host_container(host)).exec_run(plan.WIPE_SHM)
        self._remove(lambda f: f == plan.PowerCut(host))
        started = []
        for service in plan.boot_order(testrun.boot_services(self._project), host):
            if service in self._services() and not self._running(service):
                self._container(service).start()
                started.append(service)
        return started

    def kill(self, component: str) -> None:
        """SIGKILL ``component`` (no clean shutdown); ``robot.start`` starts it again, as does the next test."""
        self._container(component).kill("SIGKILL")
        self.active.append(plan.Killed(component))

    # ------------------------------------------------------------------ what is in force, undoing it

    def describe(self) -> list[str]:
        """One line per fault in force (a killed component that was started again is no longer one)."""
        self.active = [f for f in self.active if not (isinstance(f, plan.Killed) and self._running(f.component))]
        return [f.describe() for f in self.active]

    def clear(self) -> list[str]:
        """Undo every fault: boot powered-off hosts, remove shaping and filters; return what was in force."""
        undone = self.describe()
        for fault in list(self.active):
            if isinstance(fault, plan.PowerCut):
                self.boot(fault.host)
        for host in sorted(self._shaped):
            self.unlimit_link(host)
        self.active = []
        self._refilter()
        return undone

    def close(self) -> None:
        """Remove the fault agents (the run's end)."""
        for agent in self._agents.values():
            with contextlib.suppress(Exception):
                agent.remove(force=True)
        self._agents.clear()

    # ------------------------------------------------------------------ Docker

    def _running(self, service: str) -> bool:
        container = self._container(service)
        container.reload()
        return bool(container.status == "running")

    def _add(self, fault: plan.Fault) -> None:
        if fault not in self.active:
            self.active.append(fault)
        self._refilter()

    def _remove(self, which: Callable[[plan.Fault], bool]) -> None:
        self.active = [f for f in self.active if not which(f)]
        self._refilter()

    def _refilter(self) -> None:
        """Bring every host's packet filter in line with the faults in force (only those that change)."""
        addresses = {h: self._project.robot.host(h).ip for h in self.hosts}
        for host in self.hosts:
            wanted = plan.host_filter(host, self.active, addresses, self._observer_address())
            if self._filters.get(host, plan.HostFilter()) != wanted:
                self._exec(host, plan.nft_argv(wanted))
                self._filters[host] = wanted

    def _observer_address(self) -> str:
        """The test process's address on the run network: the network's gateway."""
        if self._observer is None:
            network = self._client.networks.get(self._run.network)
            self._observer = str(network.attrs["IPAM"]["Config"][0]["Gateway"])
        return self._observer

    def _has_netem(self, host: str) -> bool:
        if self._netem is None:
            code, _ = self._agent(host).exec_run(plan.netem_probe_argv())
            self._netem = code == 0
        return self._netem

    def _exec(self, host: str, argv: list[str]) -> None:
        code, output = self._agent(host).exec_run(argv)
        if code != 0:
            text = output.decode(errors="replace").strip()
            raise FaultError(f"host {host}: {argv[3]} failed (exit {code}): {text[-400:]}")

    def _agent(self, host: str) -> Any:
        """The fault agent of ``host``, started on first use."""
        agent = self._agents.get(host)
        if agent is None:
            labels = {**self._run.labels, naming.LABEL_ROLE: plan.ROLE_AGENT,
                      naming.LABEL_PROJECT: self._run.label_project}
            agent = self._client.containers.run(
                agent_image(self._client, testrun.host_spec(self._run, self._project, host).image),
                entrypoint=list(plan.AGENT_COMMAND[:1]), command=list(plan.AGENT_COMMAND[1:]),
                name=self._run.fault_agent(host), network_mode=f"container:{self._run.host_container(host)}",
                cap_add=["NET_ADMIN"], labels=labels, detach=True, user="root")
            self._agents[host] = agent
        return agent


def agent_image(client: Any, base: str) -> str:
    """The fault agent image made from ``base`` (built on first use, then found by its tag)."""
    from robocore.adapters.image_builder import build_image, image_state

    state = image_state(client, base)
    if state is None:
        raise FaultError(f"the robot's base image {base} is gone: the fault agent is made from it")
    tag = state.id.split(":")[-1][:12]
    ref = f"{AGENT_IMAGE}:{tag}"
    if image_state(client, ref) is None:
        image = ImagePlan(role="faults", name=AGENT_IMAGE, tag=tag, arch=state.arch,
                          dockerfile=plan.agent_dockerfile(base), parent=base)
        build_image(client, image, (), labels={naming.LABEL_ROLE: plan.ROLE_AGENT}, native_arch=state.arch)
    return ref
