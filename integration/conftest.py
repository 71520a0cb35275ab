"""Shared fixtures of the Docker integration suites.

- ``docker_client``: a docker-py client of the local daemon; FAILS (never skips) without one.
- ``demo_project``: one session-wide robot project (``robocore init --defaults --base wheels``)
  taken through ``prepare-base``, ``stage`` and ``build``. Its folder name is fixed, so its
  images (``robocore-it-demo-*``) survive between runs and a rerun is a cheap no-op thanks to the
  content-hash labels; the images are the cache and are kept on purpose.
- ``run_robocore``: run ``python -m robocore -p PROJECT ...`` and return the completed process.

Containers created by tests must be removed by the tests themselves; name them with a
``robocore-it-`` prefix so a leftover is easy to spot.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import textwrap
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

os.environ.setdefault("TESTCONTAINERS_RYUK_DISABLED", "true")

DEMO_NAME = "robocore-it-demo"
RunRobocore = Callable[..., "subprocess.CompletedProcess[str]"]


def _robocore(
    project: Path | None, *args: str, check: bool = True, timeout: float = 1800
) -> subprocess.CompletedProcess[str]:
    argv = [sys.executable, "-m", "robocore"]
    if project is not None:
        argv += ["-p", str(project)]
    argv += list(args)
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=timeout)
    if check and proc.returncode != 0:
        pytest.fail(
            f"`robocore {' '.join(args)}` exited {proc.returncode}\n--- stdout\n{proc.stdout[-4000:]}\n"
            f"--- stderr\n{proc.stderr[-4000:]}",
            pytrace=False,
        )
    return proc


@pytest.fixture(scope="session")
def run_robocore() -> RunRobocore:
    """``run_robocore(project, *args, check=True)`` runs the robocore CLI in a subprocess."""
    return _robocore


@pytest.fixture(scope="session")
def docker_client() -> Iterator[object]:
    """A client of the local Docker daemon. Fails loudly when there is none."""
    try:
        import docker

        client = docker.from_env(timeout=300)
        client.ping()
    except Exception as exc:
        pytest.fail(
            f"the integration suites need a reachable Docker daemon (DOCKER_HOST or /var/run/docker.sock): {exc}",
            pytrace=False,
        )
    yield client
    client.close()


# A minimal stand-in for the copier template, used only while `robocore init` is not implemented.
_MINIMAL_ROBOT = """\
ros_distro: jazzy
ros_domain_id: 0
base:
  kind: wheels
hosts:
  - name: devmachine
    ip: 127.0.0.1
components:
  - name: talker
    runs_on: devmachine
    folder: components/talker
    entrypoint: ros2 run demo_talker talker
  - name: listener
    runs_on: devmachine
    folder: components/listener
    entrypoint: ros2 run demo_listener listener
"""

_NODE = {
    "talker": '''\
import rclpy
from rclpy.node import Node
from std_msgs.msg import String


class Talker(Node):
    def __init__(self):
        super().__init__("talker")
        self.pub = self.create_publisher(String, "chatter", 10)
        self.count = 0
        self.create_timer(0.5, self.tick)

    def tick(self):
        msg = String()
        msg.data = f"Hello World: {self.count}"
        self.count += 1
        self.get_logger().info(f"Publishing: '{msg.data}'")
        self.pub.publish(msg)


def main():
    rclpy.init()
    rclpy.spin(Talker())
''',
    "listener": '''\
import rclpy
from rclpy.node import Node
from std_msgs.msg import String


class Listener(Node):
    def __init__(self):
        super().__init__("listener")
        self.create_subscription(String, "chatter", self.heard, 10)

    def heard(self, msg):
        self.get_logger().info(f"I heard: '{msg.data}'")


def main():
    rclpy.init()
    rclpy.spin(Listener())
''',
}


def write_minimal_project(root: Path) -> None:
    """A two-component (talker, listener) wheels project equivalent to the template's defaults."""
    root.mkdir(parents=True, exist_ok=True)
    (root / "robot.yaml").write_text(_MINIMAL_ROBOT)
    for role, code in _NODE.items():
        pkg = f"demo_{role}"
        base = root / "components" / role / "src" / pkg
        (base / pkg).mkdir(parents=True, exist_ok=True)
        (base / "resource").mkdir(exist_ok=True)
        (base / "resource" / pkg).write_text("")
        (base / pkg / "__init__.py").write_text("")
        (base / pkg / f"{role}.py").write_text(code)
        (base / "package.xml").write_text(textwrap.dedent(f"""\
            <?xml version="1.0"?>
            <package format="3">
              <name>{pkg}</name>
              <version>0.1.0</version>
              <description>Demo {role}</description>
              <maintainer email="dev@example.com">dev</maintainer>
              <license>Apache-2.0</license>
              <exec_depend>rclpy</exec_depend>
              <exec_depend>std_msgs</exec_depend>
              <export><build_type>ament_python</build_type></export>
            </package>
            """))
        (base / "setup.cfg").write_text(
            f"[develop]\nscript_dir=$base/lib/{pkg}\n[install]\ninstall_scripts=$base/lib/{pkg}\n"
        )
        (base / "setup.py").write_text(textwrap.dedent(f"""\
            from setuptools import setup

            setup(
                name="{pkg}",
                version="0.1.0",
                packages=["{pkg}"],
                data_files=[
                    ("share/ament_index/resource_index/packages", ["resource/{pkg}"]),
                    ("share/{pkg}", ["package.xml"]),
                ],
                install_requires=["setuptools"],
                entry_points={{"console_scripts": ["{role} = {pkg}.{role}:main"]}},
            )
            """))


def make_demo_project(parent: Path, name: str = DEMO_NAME) -> Path:
    """``robocore init PARENT/NAME --defaults --base wheels`` (or the minimal stand-in while init is missing)."""
    root = parent / name
    if root.exists():
        shutil.rmtree(root)
    proc = _robocore(None, "init", str(root), "--defaults", "--base", "wheels", check=False)
    if proc.returncode == 3 and "not implemented" in proc.stderr:
        write_minimal_project(root)
    elif proc.returncode != 0:
        pytest.fail(f"robocore init failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}", pytrace=False)
    return root


@pytest.fixture(scope="session")
def demo_project(docker_client: object) -> Iterator[Path]:
    """The template project (wheels base) after prepare-base, stage and build; returns its folder."""
    parent = Path(tempfile.mkdtemp(prefix="robocore-it-"))
    root = make_demo_project(parent)
    for step in ("prepare-base", "stage", "build"):
        _robocore(root, step, "--quiet")
    yield root
    shutil.rmtree(parent, ignore_errors=True)
