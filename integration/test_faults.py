"""Faults in the ``robot`` fixture on a two-host robot, through the pytest plugin as a robot team runs it.

One pytest session (one bring-up) runs ``graph_suites/faults_two_hosts.py`` in a copy of the demo
project with the talker and discovery server 0 on host ``main``, the listener and discovery server 1
on host ``arm``: a control window without a fault, then a cut-off and reconnection, a partition,
a limited link, power cuts of either host and their boots, a SIGKILLed component, each discovery server
killed in turn (no message lost, a node started during the outage heard), and a test that
fails on purpose with faults in force (its report lists them; the next test finds them undone).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from deploy_helpers import free_udp_port, output_tails

pytestmark = pytest.mark.docker

SUITES = Path(__file__).parent / "graph_suites"


def two_hosts_two_servers(data: dict[str, Any]) -> None:
    """robot.yaml: talker on ``main``, listener on ``arm``, one discovery server on each."""
    first = data["hosts"][0]
    first.update(name="main", ip="192.0.2.9", user="root")
    data["hosts"] = [first, {**first, "name": "arm", "ip": "192.0.2.10"}]
    data["components"][0]["runs_on"] = "main"
    data["components"][1]["runs_on"] = "arm"
    port = free_udp_port()
    data["discovery"]["servers"] = [{"host": "main", "port": port}, {"host": "arm", "port": port}]


def run_suite(project_copies: Callable[..., Path], suite: str, edit: Callable[[dict[str, Any]], None],
              *args: str) -> subprocess.CompletedProcess[str]:
    """``suite`` as ``tests/graph/test_suite.py`` of a new copy of the demo project, run by pytest."""
    root = project_copies("faults", edit=edit)
    (root / "tests" / "graph").mkdir(parents=True)
    shutil.copy(SUITES / suite, root / "tests" / "graph" / "test_suite.py")
    return subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q", "-s", "tests/graph", *args],
                          cwd=root, capture_output=True, text=True, timeout=900, env=dict(os.environ))


def figures(proc: subprocess.CompletedProcess[str]) -> dict[str, float]:
    """The ``FIGURE name value`` lines the suite printed."""
    return {name: float(value) for name, value in re.findall(r"FIGURE (\w+) ([0-9.]+)", proc.stdout)}


@pytest.mark.quiet
def test_every_fault_is_observed_and_undone_on_a_two_host_robot(project_copies: Callable[..., Path]) -> None:
    proc = run_suite(project_copies, "faults_two_hosts.py", two_hosts_two_servers)
    print(figures(proc), re.findall(r"NOTE [^\n]*", proc.stdout))
    assert "1 failed, 10 passed" in proc.stdout, output_tails(proc, 12000)
    failed = proc.stdout.split("test_zz_a_failing_test_with_a_fault_in_force", 1)[1]
    assert "robocore: faults in force" in failed, output_tails(proc)
    assert "host arm cut off from the network" in failed, output_tails(proc)
    assert "host main link limited to 1000 kbit/s, 5 % loss" in failed, output_tails(proc)
    assert "FAILED tests/graph/test_suite.py::test_zz_a_failing_test_with_a_fault_in_force" in proc.stdout
