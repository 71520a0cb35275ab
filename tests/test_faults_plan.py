"""Faults of a robot under test as data: filters per host, nft rulesets, tc argv, boots (no Docker)."""

from __future__ import annotations

import pytest

from robocore.errors import UsageError
from robocore.plan import faults
from robocore.plan.faults import CutOff, HostFilter, Killed, LinkLimit, Partition, PowerCut
from robocore.plan.testrun import TestRun
from robocore.project import Project

TWO_HOSTS = """\
ros_distro: jazzy
image_prefix: demo-
base: {kind: wheels}
hosts:
  - {name: main, ip: 192.168.1.10, user: robot}
  - {name: arm, ip: 192.168.1.11, user: robot}
components:
  - {name: talker, folder: components/talker, runs_on: main, entrypoint: ros2 run demo_talker talker}
  - {name: listener, folder: components/listener, runs_on: arm, entrypoint: ros2 run demo_listener listener,
     restart: "no"}
"""
HOSTS = ["main", "arm", "spare"]
ADDRESSES = {"main": "172.30.0.2", "arm": "172.30.0.3", "spare": "172.30.0.4"}
OBSERVER = "172.30.0.1"


def _filter(host: str, *active: faults.Fault) -> HostFilter:
    return faults.host_filter(host, active, ADDRESSES, OBSERVER)


def test_no_fault_no_filter() -> None:
    assert _filter("main").empty
    assert _filter("main", Killed("talker")).empty


def test_a_cut_off_host_drops_everything_and_the_others_nothing() -> None:
    assert _filter("arm", CutOff("arm")) == HostFilter(drop_all=True)
    assert _filter("main", CutOff("arm")).empty


def test_a_power_cut_host_is_off_the_network_too() -> None:
    assert _filter("arm", PowerCut("arm")).drop_all


def test_a_partition_blocks_the_other_groups_and_the_observer_stays_with_the_first() -> None:
    split = faults.partition([["main"], ["arm", "spare"]], HOSTS)
    assert _filter("main", split).blocked == {"172.30.0.3", "172.30.0.4"}
    assert _filter("arm", split).blocked == {"172.30.0.2", OBSERVER}
    assert _filter("spare", split).blocked == {"172.30.0.2", OBSERVER}


def test_a_lossy_link_drops_per_mille_on_its_host_only() -> None:
    lossy = LinkLimit("arm", None, 12.5)
    assert _filter("arm", lossy) == HostFilter(loss_permille=125)
    assert _filter("main", lossy).empty


@pytest.mark.parametrize("groups, message", [
    ([["main", "arm", "spare"]], "at least two groups"),
    ([["main"], []], "at least two groups"),
    ([["main"], ["arm"]], "spare in no group"),
    ([["main", "arm"], ["arm", "spare"]], "arm in more than one group"),
    ([["main"], ["arm", "nowhere"], ["spare"]], "no robot host 'nowhere' in this run (hosts: main, arm, spare)"),
])
def test_bad_partitions_are_refused_in_one_line(groups: list[list[str]], message: str) -> None:
    with pytest.raises(UsageError, match=message.replace("(", r"\(").replace(")", r"\)")):
        faults.partition(groups, HOSTS)


@pytest.mark.parametrize("kwargs, message", [
    ({"rate_kbit": 0, "loss_percent": 0, "delay_ms": 0}, "positive number of kbit/s"),
    ({"rate_kbit": True, "loss_percent": 0, "delay_ms": 0}, "positive number of kbit/s"),
    ({"rate_kbit": None, "loss_percent": 100, "delay_ms": 0}, "from 0 to below 100"),
    ({"rate_kbit": None, "loss_percent": 0, "delay_ms": -1}, ">= 0"),
    ({"rate_kbit": None, "loss_percent": 0, "delay_ms": 0}, "needs a rate, a loss or a delay"),
])
def test_bad_link_limits_are_refused(kwargs: dict[str, object], message: str) -> None:
    with pytest.raises(UsageError, match=message):
        faults.link_limit("main", **kwargs)  # type: ignore[arg-type]


def test_the_nft_ruleset_replaces_the_table_in_one_transaction() -> None:
    text = faults.nft_ruleset(HostFilter(blocked=frozenset({"172.30.0.4", "172.30.0.3"}), loss_permille=50))
    assert text.startswith("table inet robocore_faults {}\ndelete table inet robocore_faults\n")
    assert 'iifname "lo" accept' in text and 'oifname "lo" accept' in text
    assert "ip saddr { 172.30.0.3, 172.30.0.4 } counter drop" in text
    assert "ip daddr { 172.30.0.3, 172.30.0.4 } counter drop" in text
    assert text.count("numgen random mod 1000 < 50 counter drop") == 2


def test_an_empty_filter_only_removes_the_table() -> None:
    assert faults.nft_ruleset(HostFilter()) == "table inet robocore_faults {}\ndelete table inet robocore_faults\n"


def test_a_cut_off_ruleset_drops_all_but_loopback() -> None:
    text = faults.nft_ruleset(HostFilter(drop_all=True))
    assert text.count("counter drop") == 2 and "ip saddr" not in text


def test_an_address_that_is_not_one_never_reaches_nft() -> None:
    with pytest.raises(ValueError):
        faults.nft_ruleset(HostFilter(blocked=frozenset({"1.2.3.4; flush ruleset"})))


def test_the_ruleset_reaches_nft_as_an_argument_of_a_fixed_script() -> None:
    argv = faults.nft_argv(HostFilter(drop_all=True))
    assert argv[:4] == ["sh", "-c", faults.NFT_SCRIPT, "robocore-nft"]
    assert "$" not in argv[2].replace("$1", "")
    assert argv[4] == faults.nft_ruleset(HostFilter(drop_all=True))


def test_shaping_argv_carries_values_as_positional_arguments() -> None:
    argv = faults.shape_argv(800)
    assert argv[:4] == ["sh", "-c", faults.SHAPE_SCRIPT, "robocore-shape"]
    assert argv[4:] == ["eth0", "800kbit", str(16 * 1024), "400ms", ""]
    assert faults.shape_argv(None, 30)[5:] == ["", "", "400ms", "30ms"]
    assert faults.burst_bytes(100_000) == 250_000  # 20 ms at 100 Mbit/s
    assert faults.unshape_argv()[3:] == ["robocore-unshape", "eth0"]


def test_a_rate_limit_polices_what_the_host_receives() -> None:
    limited = _filter("arm", LinkLimit("arm", 800))
    assert limited.ingress_bytes_per_s == 100_000 and not limited.empty
    text = faults.nft_ruleset(limited)
    assert text.count("limit rate over 100000 bytes/second burst 16384 bytes counter drop") == 1
    assert text.index("limit rate") < text.index("chain output")


def test_a_boot_starts_servers_first_and_only_what_the_restart_policy_starts() -> None:
    services = {
        "talker": ("main", "component", "unless-stopped"),
        "discovery-0": ("main", "discovery", "unless-stopped"),
        "once": ("main", "component", "no"),
        "listener": ("arm", "component", "always"),
        "flaky": ("main", "component", "on-failure"),
    }
    assert faults.boot_order(services, "main") == ["discovery-0", "talker", "flaky"]
    assert faults.boot_order(services, "arm") == ["listener"]


def test_descriptions_name_the_fault() -> None:
    assert CutOff("arm").describe() == "host arm cut off from the network"
    assert Partition((("main",), ("arm", "spare"))).describe() == \
        "partition main | arm, spare (test process with the first)"
    assert LinkLimit("arm", 800, 2.5).describe() == "host arm link limited to 800 kbit/s, 2.5 % loss"
    assert PowerCut("arm").describe() == "host arm powered off (every process SIGKILLed)"
    assert Killed("talker").describe() == "component talker SIGKILLed"


def test_the_agent_image_adds_only_nftables_and_iproute2() -> None:
    text = faults.agent_dockerfile("demo-base:latest")
    assert text.startswith("FROM demo-base:latest\nUSER root\n")
    assert "--no-install-recommends nftables iproute2 && rm -rf /var/lib/apt/lists/*" in text


def test_boot_services_carry_the_robots_restart_policies(make_project) -> None:  # type: ignore[no-untyped-def]
    from robocore.plan import testrun

    root = make_project(TWO_HOSTS, folders=("components/talker", "components/listener"), name="demo")
    project = Project.load(root)
    services = testrun.boot_services(project)
    assert services == {"discovery-0": ("main", "discovery", "unless-stopped"),
                        "talker": ("main", "component", "unless-stopped"),
                        "listener": ("arm", "component", "no")}
    assert TestRun("demo", "0123abcd", 1, "o").fault_agent("arm") == "demo-t0123abcd-faults-arm"
