"""prepare-base, stage and build against a real Docker daemon, with real rclpy nodes.

The session's ``demo_project`` (conftest) is the template project on the wheels base, taken
from zero (nothing pullable: the Debian root image is bootstrapped) through prepare-base, stage
and build. These tests prove what came out of it.
"""

from __future__ import annotations

import contextlib
import json
import os
import random
import re
import shlex
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from robocore.config.model import Component
from robocore.plan import naming
from robocore.project import Project

pytestmark = pytest.mark.docker

PREFIX = "robocore-it-img"


def _project(root: Path) -> Project:
    return Project.load(root)


def _role(project: Project, role: str) -> Component:
    for comp in project.robot.components:
        if role in comp.name or role in (comp.entrypoint or ""):
            return comp
    raise AssertionError(f"the demo project has no {role} component: {[c.name for c in project.robot.components]}")


def _image(project: Project, comp: Component) -> str:
    return f"{naming.component_image(project.robot, project.name, comp.name)}:latest"


def _start(client: Any, project: Project, comp: Component, command: list[str], domain: int) -> Any:
    install = project.build_dir(comp.name) / "install"
    return client.containers.run(
        _image(project, comp), command, name=f"{PREFIX}-{comp.name}-{uuid.uuid4().hex[:8]}", detach=True,
        network_mode="host", ipc_mode="host", environment={"ROS_DOMAIN_ID": str(domain)},
        volumes={str(install): {"bind": naming.CONTAINER_INSTALL, "mode": "ro"}},
        labels={"dev.robocore.test": PREFIX},
    )


@pytest.fixture
def containers(docker_client: Any) -> Iterator[list[Any]]:
    started: list[Any] = []
    yield started
    for container in started:
        with contextlib.suppress(Exception):
            container.remove(force=True)


def _logs(container: Any) -> str:
    return str(container.logs().decode("utf-8", "replace"))


def _quoted(text: str) -> set[str]:
    """The payload of each log line: quoted text if any, else what follows the last ': '."""
    found: set[str] = set()
    for line in text.splitlines():
        quoted = re.findall(r"'([^']+)'", line) + re.findall(r'"([^"]+)"', line)
        if quoted:
            found.update(quoted)
        elif ": " in line:
            found.add(line.rsplit(": ", 1)[1].strip())
    return found


def test_talker_and_listener_exchange_messages(docker_client: Any, demo_project: Path, containers: list[Any]) -> None:
    project = _project(demo_project)
    talker, listener = _role(project, "talker"), _role(project, "listener")
    assert talker.entrypoint and listener.entrypoint
    domain = random.randint(150, 220)  # a domain of our own: other suites share the host network
    containers.append(_start(docker_client, project, talker, shlex.split(talker.entrypoint), domain))
    containers.append(_start(docker_client, project, listener, shlex.split(listener.entrypoint), domain))
    # negative control: the same listener on another domain must hear nothing
    containers.append(_start(docker_client, project, listener, shlex.split(listener.entrypoint), domain + 1))
    graph = None
    deadline = time.monotonic() + 40
    heard: set[str] = set()
    while time.monotonic() < deadline:
        time.sleep(2)
        published = _quoted(_logs(containers[0]))
        heard = published & _quoted(_logs(containers[1]))
        if heard and graph is None:
            # the ros2 command of the image sees the running nodes (a graph query over DDS)
            graph = docker_client.containers.run(
                _image(project, listener),
                ["bash", "-c", "ros2 node list --no-daemon --spin-time 2 && ros2 topic list --no-daemon --spin-time 2"],
                network_mode="host", ipc_mode="host", environment={"ROS_DOMAIN_ID": str(domain)}, remove=True,
                name=f"{PREFIX}-graph-{uuid.uuid4().hex[:8]}",
            ).decode()
            break
    talker_out, listener_out, control_out = (_logs(c) for c in containers)
    assert heard, (f"listener heard nothing the talker published.\ntalker:\n{talker_out[-1500:]}\n"
                   f"listener:\n{listener_out[-1500:]}")
    assert _quoted(talker_out) and not (_quoted(talker_out) & _quoted(control_out)), (
        f"the listener on another ROS_DOMAIN_ID heard the talker:\n{control_out[-1500:]}")
    assert graph is not None and "/talker" in graph and "/listener" in graph and "/chatter" in graph, graph


def test_build_outputs_are_owned_by_the_invoking_user(demo_project: Path) -> None:
    build_root = demo_project / ".robocore" / "build"
    owners = {p.stat().st_uid for p in build_root.rglob("*") if not p.is_symlink()}
    assert owners == {os.getuid()}
    project = _project(demo_project)
    for comp in project.robot.components:
        if comp.folder:
            assert (project.build_dir(comp.name) / "install" / "setup.bash").is_file()


def _image_ids(client: Any, project: Project) -> dict[str, str]:
    refs = [f"{naming.base_image(project.robot, project.name)}:latest"]
    refs += [_image(project, c) for c in project.robot.components if c.image is None]
    return {ref: client.images.get(ref).id for ref in refs}


def test_second_prepare_base_and_stage_are_no_ops(docker_client: Any, demo_project: Path, run_robocore: Any) -> None:
    project = _project(demo_project)
    before = _image_ids(docker_client, project)
    for step in ("prepare-base", "stage"):
        result = json.loads(run_robocore(demo_project, step, "--json").stdout)
        assert {r["action"] for r in result["results"]} == {"up-to-date"}, result
    assert _image_ids(docker_client, project) == before


def test_images_have_the_runtime_contract(docker_client: Any, demo_project: Path) -> None:
    project = _project(demo_project)
    base = docker_client.images.get(f"{naming.base_image(project.robot, project.name)}:latest")
    assert base.attrs["Size"] <= 550 * 1000 * 1000, base.attrs["Size"]
    assert base.attrs["Config"]["Entrypoint"] == [naming.ENTRYPOINT]
    labels = base.attrs["Config"]["Labels"]
    assert labels[naming.LABEL_PROJECT] == project.name and labels[naming.LABEL_INPUTS].startswith("sha256:")
    script = (
        "set -e; for v in ROS_DISTRO ROS_VERSION ROS_PYTHON_VERSION RMW_IMPLEMENTATION AMENT_PREFIX_PATH; "
        'do echo "$v=${!v}"; done; command -v colcon fastdds ros2 ps >/dev/null && echo tools-ok; '
        "ros2 pkg list | grep -qx rclpy && echo pkg-ok; "
        "(timeout 4 fastdds discovery -i 0 -l 127.0.0.1 -p 24811 || true) | head -5"
    )
    out = docker_client.containers.run(base.id, ["bash", "-c", script], remove=True, network_mode="host",
                                       name=f"{PREFIX}-contract-{uuid.uuid4().hex[:8]}").decode()
    assert f"ROS_DISTRO={project.robot.ros_distro.value}" in out
    assert "RMW_IMPLEMENTATION=rmw_fastrtps_cpp" in out and "ROS_VERSION=2" in out
    assert "tools-ok" in out and "pkg-ok" in out
    assert "Server is running" in out or "Server started" in out, out


def test_noop_build_then_one_edit_rebuilds_only_that_package(demo_project: Path, run_robocore: Any) -> None:
    project = _project(demo_project)
    result = json.loads(run_robocore(demo_project, "build", "--json").stdout)
    assert {r["action"] for r in result["results"]} == {"up-to-date"}, result
    talker = _role(project, "talker")
    assert talker.folder
    sources = [p for p in (demo_project / talker.folder).rglob("*.py") if p.name != "setup.py" and "talker" in p.name]
    assert sources, "no talker python file found"
    sources[0].write_text(sources[0].read_text() + "\n# edited by test_images\n")
    result = json.loads(run_robocore(demo_project, "build", "--json").stdout)
    by_name = {r["what"]: r for r in result["results"]}
    assert by_name[talker.name]["action"] == "built" and by_name[talker.name]["packages"], by_name
    others = [r for name, r in by_name.items() if name != talker.name]
    assert others and all(r["action"] == "up-to-date" for r in others), by_name
    installed = list((project.build_dir(talker.name) / "install").rglob(sources[0].name))
    assert installed and any("# edited by test_images" in p.read_text() for p in installed)


def test_failed_build_names_the_package_and_shows_its_log(demo_project: Path, run_robocore: Any) -> None:
    project = _project(demo_project)
    listener = _role(project, "listener")
    assert listener.folder
    broken = demo_project / listener.folder / "robocore_it_broken"
    broken.mkdir(parents=True)
    try:
        (broken / "package.xml").write_text(
            '<?xml version="1.0"?><package format="3"><name>robocore_it_broken</name><version>0.0.0</version>'
            "<description>x</description><maintainer email='a@b.c'>a</maintainer><license>MIT</license>"
            "<export><build_type>ament_python</build_type></export></package>")
        # identifies fine, fails when built: the package directory it names does not exist
        (broken / "setup.py").write_text(
            "from setuptools import setup\nsetup(name='robocore_it_broken', version='0.0.0', "
            "packages=['robocore_it_marker_dir'])\n")
        proc = run_robocore(demo_project, "build", "--component", listener.name, check=False)
        assert proc.returncode == 6, proc.stderr
        assert "robocore_it_broken" in proc.stderr
        assert "robocore_it_marker_dir" in proc.stderr  # the tail of the package's own log
    finally:
        import shutil

        shutil.rmtree(broken)
    run_robocore(demo_project, "build", "--component", listener.name)


def test_dry_run_prints_the_plan(demo_project: Path, run_robocore: Any) -> None:
    out = run_robocore(demo_project, "stage", "--dry-run").stdout
    assert "FROM " in out and "up to date" in out
