"""robot.yaml's per-component ``resources``: validated one line per problem, and the same values for ``run``
(Docker), compose files, Swarm services and Kubernetes pods."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
from docker.types import Resources

from robocore.adapters.swarm import service_kwargs
from robocore.config.resources import integers
from robocore.plan.containers import component_spec
from robocore.plan.kubernetes.pods import PodContext, daemon_set
from robocore.plan.swarm_services import ServiceSpec
from robocore.project import Project

ROBOT = """\
ros_distro: jazzy
hosts: [{{name: main, ip: 10.0.0.10}}]
components:
  - name: driver
    image: example.org/driver:1
    runs_on: main
{resources}
  - name: viewer
    image: example.org/viewer:1
    runs_on: main
"""
GOOD = "    resources: {requests: {cpu: 0.25, memory: 64Mi}, limits: {cpu: '1500m', memory: 1Gi}, priority: critical}"


def project(tmp_path: Path, resources: str) -> Path:
    root = tmp_path / "bot"
    root.mkdir()
    (root / "robot.yaml").write_text(ROBOT.format(resources=resources))
    return root


def test_bad_values_are_refused_one_line_each(tmp_path: Path) -> None:
    root = project(tmp_path, "    resources:\n      requests: {cpu: -1, memory: lots}\n      limits: {cpu: 0}\n"
                             "      priority: high\n      gpu: 1")
    done = subprocess.run([sys.executable, "-m", "robocore", "validate"], capture_output=True, text=True, cwd=root,
                          timeout=60)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    lines = [line for line in done.stderr.splitlines() if line.startswith("error:")]
    keys = [line.split(": ")[2] for line in lines]
    assert keys == ["components[0].resources.requests.cpu", "components[0].resources.requests.memory",
                    "components[0].resources.limits.cpu", "components[0].resources.priority",
                    "components[0].resources.gpu"], lines
    assert all(line.split(": ")[1].startswith("robot.yaml:") for line in lines)
    assert "500m" in lines[0] and "256Mi" in lines[1]


def test_a_request_above_its_limit_is_refused(tmp_path: Path) -> None:
    root = project(tmp_path, "    resources: {requests: {memory: 2Gi}, limits: {memory: 1Gi}}")
    done = subprocess.run([sys.executable, "-m", "robocore", "validate"], capture_output=True, text=True, cwd=root,
                          timeout=60)
    assert done.returncode == 2
    (line,) = [line for line in done.stderr.splitlines() if line.startswith("error:")]
    assert "components[0].resources" in line and "requests.memory is more than limits.memory" in line


def test_the_same_values_reach_docker_compose_swarm_and_pods(tmp_path: Path) -> None:
    loaded = Project.load(project(tmp_path, GOOD))
    driver, viewer = (component_spec(loaded, c) for c in loaded.robot.components)
    kwargs = driver.docker_kwargs()
    assert (kwargs["nano_cpus"], kwargs["cpu_shares"]) == (1_500_000_000, 256)
    assert (kwargs["mem_limit"], kwargs["mem_reservation"]) == (1 << 30, 64 << 20)
    assert kwargs["oom_score_adj"] == -900
    assert not {"nano_cpus", "mem_limit", "oom_score_adj"} & set(viewer.docker_kwargs())  # none given: none set
    compose = driver.compose_service()
    assert (compose["cpus"], compose["mem_limit"], compose["mem_reservation"]) == (1.5, 1 << 30, 64 << 20)
    service = ServiceSpec(name="s", robot="r1", component="driver", role="component", image="x@sha256:" + "0" * 64,
                          command=None, args=None, environment=(), mounts=(), configs=(), constraints=(),
                          restart="any", limits=driver.limits)
    assert service_kwargs(service, {})["resources"] == Resources(cpu_limit=1_500_000_000, mem_limit=1 << 30,
                                                                 cpu_reservation=250_000_000,
                                                                 mem_reservation=64 << 20)
    context = PodContext(model="bot", arch="amd64", image="bot-driver-amd64", wait_image="bot-base-amd64",
                         dds_config_map=None, discovery_names=(), advertised_names=frozenset())
    pod = daemon_set("driver", driver, context)["spec"]["template"]["spec"]
    assert pod["containers"][0]["resources"] == {"requests": {"cpu": "250m", "memory": str(64 << 20)},
                                                 "limits": {"cpu": "1500m", "memory": str(1 << 30)}}
    assert pod["priorityClassName"] == "system-node-critical"
    assert "resources" not in daemon_set("viewer", viewer, context)["spec"]["template"]["spec"]["containers"][0]


def test_resources_are_part_of_the_spec_hash(tmp_path: Path) -> None:
    """A change of resources recreates the container. (A spec without resources keeps the hash it had before the
    key existed: the golden compose files' spec labels, tests/test_compose.py, did not change.)"""
    from dataclasses import replace

    loaded = Project.load(project(tmp_path, GOOD))
    driver = component_spec(loaded, loaded.robot.components[0])
    assert replace(driver, limits=None).spec_hash != driver.spec_hash


@pytest.mark.parametrize(("low", "high"), [(1, 1), (1, 9), (5, 123), (999, 1000), (1, 1024), (7, 7000), (6144, 99999)])
def test_the_schemas_integer_ranges_match_exactly_the_integers_between(low: int, high: int) -> None:
    """The schema's size and CPU patterns are built from ranges of integers: each takes exactly ``low..high``
    (leading zeros allowed, as the model's int() does), so an editor calls fine only what validate takes."""
    pattern = re.compile(f"^{integers(low, high)}$")
    for number in range(0, high + 1100):
        assert bool(pattern.match(str(number))) == (low <= number <= high), number
        assert bool(pattern.match(f"00{number}")) == (low <= number <= high), number
