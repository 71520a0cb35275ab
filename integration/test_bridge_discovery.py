"""A component on a bridge network (it lists ``ports``) on a host at 127.0.0.1 reaches the discovery server.

The demo project's host is 127.0.0.1, and the discovery server runs there with host networking. A bridge
container's 127.0.0.1 is its own, so robocore hands it ``host.docker.internal`` (mapped to the bridge's
gateway by ``extra_hosts: host-gateway``). Control: the same listener given the loopback address
(``environment`` overrides robocore's value) hears nothing.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml
from deploy_helpers import HEARD, copy_project, free_tcp_port, log_lines, remove_project_containers, wait_for

pytestmark = pytest.mark.docker

HEAR_WITHIN = 60.0
#: How long the control listener is given to hear something it must not.
SILENT_FOR = 25.0


@pytest.fixture
def names(docker_client: Any) -> Iterator[list[str]]:
    made: list[str] = []
    yield made
    for name in made:
        remove_project_containers(docker_client, name)


def bridge_listener(demo_project: Path, parent: Path, name: str) -> Path:
    """A copy of the demo project whose listener publishes a port (so runs on a bridge network)."""
    port = free_tcp_port()

    def edit(data: dict[str, Any]) -> None:
        listener = next(c for c in data["components"] if c["name"] == "listener")
        listener["ports"] = [f"127.0.0.1:{port}:{port}"]

    return copy_project(demo_project, parent, name, edit=edit)


def test_a_bridge_listener_hears_the_talker_through_the_hosts_discovery_server(
        demo_project: Path, tmp_path: Path, docker_client: Any, run_robocore: Any, names: list[str]) -> None:
    name = f"robocore-it-bridge-{int(time.time() * 1000) % 100000}"
    names.append(name)
    root = bridge_listener(demo_project, tmp_path, name)
    run_robocore(root, "run", "--quiet")
    listener = docker_client.containers.get(f"{name}-listener")
    assert listener.attrs["HostConfig"]["NetworkMode"] == "bridge"
    env = dict(item.split("=", 1) for item in listener.attrs["Config"]["Env"])
    assert env["ROS_DISCOVERY_SERVER"].startswith("host.docker.internal:")
    assert "host.docker.internal:host-gateway" in listener.attrs["HostConfig"]["ExtraHosts"]
    assert wait_for(lambda: log_lines(listener, HEARD), HEAR_WITHIN), (
        "the bridge listener heard nothing:\n" + listener.logs().decode(errors="replace")[-2000:])


def test_control_the_same_listener_given_loopback_hears_nothing(
        demo_project: Path, tmp_path: Path, docker_client: Any, run_robocore: Any, names: list[str]) -> None:
    name = f"robocore-it-bridge-lo-{int(time.time() * 1000) % 100000}"
    names.append(name)
    root = bridge_listener(demo_project, tmp_path, name)
    data = yaml.safe_load((root / "robot.yaml").read_text())
    port = data["discovery"]["servers"][0]["port"]
    listener_entry = next(c for c in data["components"] if c["name"] == "listener")
    listener_entry["environment"] = {"ROS_DISCOVERY_SERVER": f"127.0.0.1:{port}"}
    (root / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    run_robocore(root, "run", "--quiet")
    talker = docker_client.containers.get(f"{name}-talker")
    listener = docker_client.containers.get(f"{name}-listener")
    assert wait_for(lambda: log_lines(talker, "Publishing"), HEAR_WITHIN), "the talker did not publish"
    time.sleep(SILENT_FOR)
    assert log_lines(listener, HEARD) == [], "a bridge listener pointed at its own loopback heard the talker"
    assert listener.attrs["HostConfig"]["NetworkMode"] == "bridge"
