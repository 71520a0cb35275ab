"""Plain helpers shared by the integration suites (fixtures are in conftest.py).

- polling: :func:`wait_for` (from bench/robot_host/polling.py, which the robot hosts and bench scripts use too);
- logs: :func:`log_lines` (the lines of a container's log holding a marker);
- ports: :func:`free_udp_port`, :func:`free_tcp_port`;
- projects: :func:`copy_project`, a throw-away copy of the session's demo project with its own
  discovery port and ROS domain, so that suites running at the same time on one Docker host never
  share a discovery server or a graph; :func:`remove_project_containers` and
  :func:`remove_test_runs`, what fixture finalizers use to remove what a project left;
- output: :func:`output_tails`, the exit code and the ends of a process's output for a failure message;
- a project's own checks: :func:`run_nox`;
- tools: :func:`compose_command`.
"""

from __future__ import annotations

import contextlib
import os
import random
import shutil
import socket
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import lanes
import pytest
import yaml
from docker.errors import NotFound
from robot_host.polling import wait_for as wait_for  # re-exported: the suites' one wait loop

HEARD = "I heard"
PUBLISHED = "Publishing"


def compose_command() -> list[str]:
    """``docker-compose`` (v1) or ``docker compose`` (v2 plugin); fails the test when neither exists."""
    if shutil.which("docker-compose"):
        return ["docker-compose"]
    probe = subprocess.run(["docker", "compose", "version"], capture_output=True)
    if probe.returncode == 0:
        return ["docker", "compose"]
    pytest.fail("the compose tests need docker-compose (apt-get install docker-compose) or the compose v2 plugin",
                pytrace=False)


def free_udp_port() -> int:
    """A UDP port nobody listens on right now (host networking: the discovery server binds it), of this lane's
    ports (:func:`free_port`)."""
    return free_port(socket.SOCK_DGRAM)


def free_tcp_port() -> int:
    """A TCP port nobody listens on right now, of this lane's ports (:func:`free_port`)."""
    return free_port(socket.SOCK_STREAM)


def free_port(kind: socket.SocketKind) -> int:
    """A port of socket ``kind`` nobody listens on right now, of this lane's ports (:func:`lanes.ports`: below the
    kernel's ephemeral range, so that a port found free is not handed to some client's socket (ssh, a registry
    pull) before the server binds it, and never one another lane may pick)."""
    for _ in range(200):
        port = random.choice(lanes.ports())
        with socket.socket(socket.AF_INET, kind) as sock:
            try:
                sock.bind(("0.0.0.0", port))
            except OSError:
                continue
            return port
    raise RuntimeError(f"no free {'UDP' if kind == socket.SOCK_DGRAM else 'TCP'} port")


def output_tails(proc: subprocess.CompletedProcess[str], tail: int = 6000) -> str:
    """The exit code and the last ``tail`` characters of stdout and stderr, for a failure message."""
    out, err = (proc.stdout or "")[-tail:], (proc.stderr or "")[-tail:]
    return f"exit {proc.returncode}\n--- stdout\n{out}\n--- stderr\n{err}"


def copy_project(source: Path, parent: Path, name: str, *, transport: str = "shm",
                 edit: Callable[[dict[str, Any]], None] | None = None) -> Path:
    """A copy of the built project ``source`` named ``name``: same images (same image_prefix) and install
    trees, its own containers (the name), discovery port and ROS domain."""
    root = parent / name
    if root.exists():
        shutil.rmtree(root)
    root.mkdir(parents=True)
    shutil.copytree(source / "components", root / "components", symlinks=True)
    for install in (source / ".robocore" / "build").glob("*/install"):
        target = root / ".robocore" / "build" / install.parent.name
        shutil.copytree(install, target / "install", symlinks=True)
        for state in install.parent.glob(".robocore-*.json"):  # the build's state (what run labels)
            shutil.copy2(state, target / state.name)
    data = yaml.safe_load((source / "robot.yaml").read_text())
    data["ros_domain_id"] = lanes.new_domain()
    data["discovery"] = {"servers": [{"host": data["hosts"][0]["name"], "port": free_udp_port()}],
                         "transport": transport}
    if edit is not None:
        edit(data)
    (root / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    return root


def run_nox(root: Path, *sessions: str) -> subprocess.CompletedProcess[str]:
    """``nox --no-venv -s SESSIONS`` in project ``root`` with this interpreter's tools first on PATH."""
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    return subprocess.run([sys.executable, "-m", "nox", "--no-venv", "-s", *sessions], cwd=root, env=env,
                          capture_output=True, text=True, timeout=1800)


def log_lines(container: Any, marker: str, since: float | None = None) -> list[str]:
    """Lines of ``container``'s log containing ``marker`` (optionally only those logged after ``since``)."""
    kwargs: dict[str, Any] = {"since": int(since)} if since is not None else {}
    text = container.logs(**kwargs).decode(errors="replace")
    return [line for line in text.splitlines() if marker in line]


def project_containers(client: Any, project: str, *, all: bool = True) -> list[Any]:
    """The containers robocore made for ``project``: its label and a ``<project>-*`` name (a build's intermediate
    containers inherit the labels of the image they start from, under names of Docker's own)."""
    found = client.containers.list(all=all, filters={"label": f"dev.robocore.project={project}"}, ignore_removed=True)
    return [c for c in found if c.name.startswith(f"{project}-")]


def remove_project_containers(client: Any, project: str) -> None:
    """Remove every container named ``<project>-*`` and the project's server state volumes.

    By name, not by the project label alone: a build's intermediate containers inherit the labels of the image
    they start from (another lane may be building on this project's base image), and have names of Docker's own."""
    for container in client.containers.list(all=True, filters={"name": f"{project}-"}, ignore_removed=True):
        if container.name.startswith(f"{project}-"):
            with contextlib.suppress(NotFound):
                container.remove(force=True)
    for volume in client.volumes.list(filters={"name": f"{project}-discovery-"}):
        if volume.name.startswith(f"{project}-discovery-"):
            with contextlib.suppress(NotFound):
                volume.remove(force=True)


def remove_test_runs(client: Any, project: str) -> None:
    """Remove the containers, networks and volumes of the pytest plugin's runs of ``project`` (named
    ``<project>-t<run id>-*``), which a failed or killed run may leave behind."""
    from robocore.plan.testrun import LABEL_RUN

    prefix = f"{project}-t"
    for container in client.containers.list(all=True, filters={"label": LABEL_RUN}, ignore_removed=True):
        if container.name.startswith(prefix):
            with contextlib.suppress(NotFound):
                container.remove(force=True, v=True)
    for network in client.networks.list(filters={"label": LABEL_RUN}):
        if network.name.startswith(prefix):
            with contextlib.suppress(NotFound):
                network.remove()
    for volume in client.volumes.list(filters={"label": LABEL_RUN}):
        if volume.name.startswith(prefix):
            with contextlib.suppress(NotFound):
                volume.remove(force=True)
