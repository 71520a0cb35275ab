"""Faults of a robot under test, as data: what each host's network drops, how its link is shaped,
what a power cut stops and what the host's boot starts again.

The ``robot`` fixture (:mod:`robocore.testing.faults`) applies these plans through a small
"fault agent" container per robot host: it shares the host's network namespace
(``network_mode: container:<host>``), has ``NET_ADMIN`` and nothing else, and runs ``nft`` and
``tc`` from Debian packages. Nothing here needs root on the dev machine, and nothing touches a
namespace the run did not create.

* A host's packet filter is one nftables table (:data:`TABLE`), rebuilt from every fault in force
  whenever one is added or undone (:func:`host_filter`, :func:`nft_ruleset`): a cut-off or
  powered-off host drops everything but loopback; a partition drops the addresses of the other
  groups (the test process sits with the first group); a lossy link drops a share of packets.
* A limited link: what the host sends is shaped with ``tbf`` (:func:`shape_argv`), what it receives
  beyond the rate is dropped by its filter (an nftables ``limit``). Redirecting ingress through an
  ``ifb`` device to shape it was tried and dropped: nodes started after it never reached the test
  process's node (the listener on another host was unaffected). The kernel of the machine that runs
  the tests decides what else is there: delay needs ``netem`` (:data:`DELAY_UNAVAILABLE`).
"""

from __future__ import annotations

import ipaddress
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

from robocore.errors import UsageError

#: The nftables table that holds a host's faults (inet: IPv4 and IPv6).
TABLE = "robocore_faults"
#: The run's hosts each have one interface on the run network (the host container's only network).
INTERFACE = "eth0"
#: The fault agent's command: hold nothing, wait for ``exec``.
AGENT_COMMAND = ("sleep", "infinity")
#: What the fault agent image adds to the robot's base image (Debian and Ubuntu both name them so).
AGENT_PACKAGES = ("nftables", "iproute2")
#: The role label of fault agents (beside the run's host containers and components).
ROLE_AGENT = "testfaults"
#: Queueing allowed by the shapers before they drop: long enough for DDS's bursts of fragments.
SHAPER_LATENCY_MS = 400

DELAY_UNAVAILABLE = ("link delay needs the kernel's netem qdisc, which this machine's kernel lacks "
                     "(tc tbf/htb shape the rate, nftables drops the loss): delay cannot be emulated here")


@dataclass(frozen=True)
class CutOff:
    """Robot host ``host`` is off the network: it reaches no other host and no other host reaches it."""

    host: str

    def describe(self) -> str:
        """One line for a failed test's report."""
        return f"host {self.host} cut off from the network"


@dataclass(frozen=True)
class Partition:
    """The hosts are split into groups that cannot reach each other; the test process is in the first."""

    groups: tuple[tuple[str, ...], ...]

    def describe(self) -> str:
        """One line for a failed test's report."""
        return "partition " + " | ".join(", ".join(group) for group in self.groups) + " (test process with the first)"

    def group_of(self, host: str) -> int:
        """The index of ``host``'s group."""
        return next(i for i, group in enumerate(self.groups) if host in group)


@dataclass(frozen=True)
class LinkLimit:
    """Robot host ``host``'s link: at most ``rate_kbit`` kbit/s each way, ``loss_percent`` of packets dropped."""

    host: str
    rate_kbit: int | None = None
    loss_percent: float = 0.0
    delay_ms: int = 0

    def describe(self) -> str:
        """One line for a failed test's report."""
        parts = [f"{self.rate_kbit} kbit/s" if self.rate_kbit else "", f"{self.loss_percent:g} % loss"
                 if self.loss_percent else "", f"{self.delay_ms} ms delay" if self.delay_ms else ""]
        return f"host {self.host} link limited to " + ", ".join(p for p in parts if p)


@dataclass(frozen=True)
class PowerCut:
    """Every process of robot host ``host`` was SIGKILLed at once; the host is off until it boots."""

    host: str

    def describe(self) -> str:
        """One line for a failed test's report."""
        return f"host {self.host} powered off (every process SIGKILLed)"


@dataclass(frozen=True)
class Killed:
    """Component ``component`` was SIGKILLed and not started again yet."""

    component: str

    def describe(self) -> str:
        """One line for a failed test's report."""
        return f"component {self.component} SIGKILLed"


Fault = CutOff | Partition | LinkLimit | PowerCut | Killed


def check_host(host: str, hosts: Sequence[str]) -> str:
    """``host`` when the run has it; UsageError naming the known hosts otherwise."""
    if host not in hosts:
        raise UsageError(f"no robot host {host!r} in this run (hosts: {', '.join(hosts) or 'none'})")
    return host


def partition(groups: Sequence[Iterable[str]], hosts: Sequence[str]) -> Partition:
    """A :class:`Partition` of ``hosts`` into ``groups``: at least two, none empty, every host in exactly one."""
    out = tuple(tuple(group) for group in groups)
    if len(out) < 2 or any(not group for group in out):
        raise UsageError("a partition needs at least two groups of hosts, none of them empty")
    named = [h for group in out for h in group]
    for host in named:
        check_host(host, hosts)
    twice = sorted({h for h in named if named.count(h) > 1})
    if twice:
        raise UsageError(f"a partition names {', '.join(twice)} in more than one group")
    missing = [h for h in hosts if h not in named]
    if missing:
        raise UsageError(f"a partition must place every host of the run: {', '.join(missing)} in no group")
    return Partition(out)


def link_limit(host: str, *, rate_kbit: int | None, loss_percent: float, delay_ms: int) -> LinkLimit:
    """A checked :class:`LinkLimit`: a positive rate, a loss in [0, 100), no negative delay, and something to do."""
    if rate_kbit is not None and (isinstance(rate_kbit, bool) or not isinstance(rate_kbit, int) or rate_kbit <= 0):
        raise UsageError(f"a link rate is a positive number of kbit/s, not {rate_kbit!r}")
    if not 0 <= loss_percent < 100:
        raise UsageError(f"a link loss is a percentage from 0 to below 100, not {loss_percent!r}")
    if delay_ms < 0:
        raise UsageError(f"a link delay is a number of milliseconds >= 0, not {delay_ms!r}")
    if rate_kbit is None and not loss_percent and not delay_ms:
        raise UsageError("a link limit needs a rate, a loss or a delay")
    return LinkLimit(host, rate_kbit, float(loss_percent), int(delay_ms))


@dataclass(frozen=True)
class HostFilter:
    """What one host's packet filter does: drop everything, drop some addresses, drop a share at random."""

    drop_all: bool = False
    blocked: frozenset[str] = frozenset()
    loss_permille: int = 0
    ingress_bytes_per_s: int = 0  # what the host receives beyond this rate is dropped (0: no limit)

    @property
    def empty(self) -> bool:
        """True when the filter drops nothing (the table is removed)."""
        return not (self.drop_all or self.blocked or self.loss_permille or self.ingress_bytes_per_s)


def host_filter(host: str, faults: Iterable[Fault], addresses: Mapping[str, str], observer: str) -> HostFilter:
    """The filter of ``host`` for every fault in force; ``addresses``: host -> its run address, ``observer``:
    the test process's address on the run network."""
    drop_all = False
    blocked: set[str] = set()
    loss = rate = 0
    for fault in faults:
        if isinstance(fault, CutOff | PowerCut) and fault.host == host:
            drop_all = True
        elif isinstance(fault, Partition):
            mine = fault.group_of(host)
            blocked |= {addresses[h] for i, group in enumerate(fault.groups) if i != mine for h in group}
            if mine != 0:
                blocked.add(observer)
        elif isinstance(fault, LinkLimit) and fault.host == host:
            loss = max(loss, round(fault.loss_percent * 10))
            rate = fault.rate_kbit * 1000 // 8 if fault.rate_kbit else rate
    return HostFilter(drop_all, frozenset(blocked), loss, rate)


def _address_set(addresses: Iterable[str]) -> str:
    v4 = sorted(str(ipaddress.ip_address(a)) for a in addresses)  # ValueError on anything but an address
    return "{ " + ", ".join(v4) + " }"


def nft_ruleset(rules: HostFilter) -> str:
    """An ``nft -f`` script that replaces the host's fault table in one transaction (or only removes it)."""
    lines = [f"table inet {TABLE} {{}}", f"delete table inet {TABLE}"]
    if rules.empty:
        return "\n".join(lines) + "\n"
    chains = []
    for chain, hook, iface, peer in (("input", "input", "iifname", "saddr"), ("output", "output", "oifname", "daddr")):
        body = [f"type filter hook {hook} priority 0; policy accept;", f'{iface} "lo" accept']
        if rules.drop_all:
            body.append("counter drop")
        else:
            if rules.blocked:
                body.append(f"ip {peer} {_address_set(rules.blocked)} counter drop")
            if rules.loss_permille:
                body.append(f"numgen random mod 1000 < {rules.loss_permille} counter drop")
            if rules.ingress_bytes_per_s and chain == "input":
                body.append(f"limit rate over {rules.ingress_bytes_per_s} bytes/second "
                            f"burst {burst_bytes(rules.ingress_bytes_per_s * 8 // 1000)} bytes counter drop")
        chains.append(f"  chain {chain} {{\n" + "".join(f"    {line}\n" for line in body) + "  }")
    lines.append(f"table inet {TABLE} {{\n" + "\n".join(chains) + "\n}")
    return "\n".join(lines) + "\n"


#: Fixed script: the ruleset comes in as ``$1`` and reaches nft on its standard input, never a shell.
NFT_SCRIPT = 'printf "%s" "$1" | nft -f -'


def nft_argv(rules: HostFilter) -> list[str]:
    """argv (run in the fault agent) that installs ``rules`` as the host's fault table."""
    return ["sh", "-c", NFT_SCRIPT, "robocore-nft", nft_ruleset(rules)]


def burst_bytes(rate_kbit: int) -> int:
    """A token-bucket depth for ``rate_kbit``: 20 ms of traffic, and never less than a few full frames."""
    return max(rate_kbit * 1000 // 8 // 50, 16 * 1024)


#: Fixed script: ``$1`` interface, ``$2`` rate (empty: none), ``$3`` burst, ``$4`` latency, ``$5`` delay (empty:
#: none). What the host sends is shaped (tbf) and, with a delay, delayed (netem under the tbf).
SHAPE_SCRIPT = (
    "set -e; "
    'tc qdisc del dev "$1" root 2>/dev/null || true; '
    'if [ -n "$2" ]; then '
    'tc qdisc add dev "$1" root handle 1: tbf rate "$2" burst "$3" latency "$4"; '
    'if [ -n "$5" ]; then tc qdisc add dev "$1" parent 1:1 handle 10: netem delay "$5"; fi; '
    'elif [ -n "$5" ]; then tc qdisc add dev "$1" root handle 1: netem delay "$5"; fi'
)
#: Fixed script: remove what :data:`SHAPE_SCRIPT` added (``$1`` interface).
UNSHAPE_SCRIPT = 'tc qdisc del dev "$1" root 2>/dev/null; true'
#: Does the kernel know netem? (exit 0: yes). Tried on a new ifb device that carries nothing and is removed.
NETEM_PROBE = ('ip link add rcfault-probe type ifb && '
               'tc qdisc add dev rcfault-probe root netem delay 1ms; code=$?; ip link del rcfault-probe; exit $code')


def shape_argv(rate_kbit: int | None, delay_ms: int = 0) -> list[str]:
    """argv (run in the fault agent) that shapes what the host sends to ``rate_kbit`` kbit/s (None: no rate
    limit) and delays it by ``delay_ms`` (0: none; needs netem). What it receives is policed by its filter."""
    rate = f"{rate_kbit}kbit" if rate_kbit else ""
    burst = str(burst_bytes(rate_kbit)) if rate_kbit else ""
    delay = f"{delay_ms}ms" if delay_ms else ""
    return ["sh", "-c", SHAPE_SCRIPT, "robocore-shape", INTERFACE, rate, burst, f"{SHAPER_LATENCY_MS}ms", delay]


def unshape_argv() -> list[str]:
    """argv (run in the fault agent) that removes the host's shaping."""
    return ["sh", "-c", UNSHAPE_SCRIPT, "robocore-unshape", INTERFACE]


def netem_probe_argv() -> list[str]:
    """argv (run in the fault agent) that exits 0 when the kernel can delay packets (netem)."""
    return ["sh", "-c", NETEM_PROBE]


#: Fixed script run in a host container at boot: a power cut empties /dev/shm (tmpfs), as a real one does.
WIPE_SHM = ["sh", "-c", "find /dev/shm -mindepth 1 -delete 2>/dev/null; true"]


def starts_at_boot(restart: str) -> bool:
    """Does a container with Docker restart policy ``restart`` start when its host boots? (all but ``no``)."""
    return restart != "no"


def boot_order(services: Mapping[str, tuple[str, str, str]], host: str) -> list[str]:
    """The services of ``host`` a boot starts, discovery servers first: ``services`` maps a service to
    (its host, its role, its restart policy on the robot)."""
    mine = [(s, role) for s, (h, role, restart) in services.items() if h == host and starts_at_boot(restart)]
    return [s for s, role in mine if role == "discovery"] + [s for s, role in mine if role != "discovery"]


def agent_dockerfile(parent: str) -> str:
    """The fault agent image: the robot's base image plus nftables and iproute2 (one small layer)."""
    packages = " ".join(AGENT_PACKAGES)
    return (
        f"FROM {parent}\n"
        "USER root\n"
        "RUN apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "
        f"{packages} && rm -rf /var/lib/apt/lists/*\n"
    )
