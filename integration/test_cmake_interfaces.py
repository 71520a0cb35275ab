"""An ament_cmake interface package on the wheels base, used by rclpy nodes in other containers.

The project (sources in ``cmake_project/``): ``server`` and ``client`` each hold the interface
package ``demo_interfaces`` (one message, one service) in their workspace beside their rclpy
package; ``observer`` holds the client package only, so its install tree lacks the interfaces.
A second project has the interface package in ``common_packages`` (built into the base) instead,
on Jazzy and on Kilted.
Real images from ``prepare-base``/``stage``/``build``, real containers through the pytest plugin's
bring-up. Controls: the same client code without the interface package cannot import it, a
service nobody offers is not answered, and the observer's image got no compiler.

Run with ``-s`` to see the measured build times (no assertion is made on them).
"""

from __future__ import annotations

import getpass
import json
import os
import shutil
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
import yaml

if TYPE_CHECKING:
    from conftest import RobocoreCli

pytestmark = pytest.mark.docker

SOURCES = Path(__file__).parent / "cmake_project"
NAME = "robocore-it-cmake"  # fixed: its images survive between runs (content-hash labels make reruns cheap)
WORKSPACES = {
    "server": ("demo_interfaces", "demo_server"),
    "client": ("demo_interfaces", "demo_client"),
    "observer": ("demo_client",),
}
ANSWER_WITHIN = 60.0
TIMES: dict[str, float] = {}


#: Seconds a robocore step of these tests may take (a cold stage compiles type support on 2 cores).
STEP_TIMEOUT = 3000


def _timed(cli: RobocoreCli, key: str, root: Path, *args: str) -> dict[str, Any]:
    start = time.monotonic()
    proc = cli(root, *args, "--json", timeout=STEP_TIMEOUT)
    TIMES[key] = time.monotonic() - start
    print(f"\n{key}: {TIMES[key]:.1f} s", flush=True)
    result: dict[str, Any] = json.loads(proc.stdout)
    return result


def _built(result: dict[str, Any]) -> dict[str, list[str]]:
    """component -> packages colcon built, for the components that were built."""
    return {r["what"]: r["packages"] for r in result["results"] if r["action"] == "built"}


def _make_project(parent: Path, name: str = NAME, workspaces: dict[str, tuple[str, ...]] = WORKSPACES,
                  common: tuple[str, ...] = (), distro: str = "jazzy") -> Path:
    root = parent / name
    for component, packages in workspaces.items():
        for package in packages:
            shutil.copytree(SOURCES / package, root / "components" / component / "src" / package)
    for package in common:
        shutil.copytree(SOURCES / package, root / "common" / package)
    entrypoints = {"server": "ros2 run demo_server server", "client": "ros2 run demo_client client",
                   "observer": "sleep infinity"}
    robot = {
        "ros_distro": distro,
        "image_prefix": f"{name}-",
        "base": {"kind": "wheels"},
        "hosts": [{"name": "dev", "ip": "127.0.0.1", "user": getpass.getuser()}],
        "common_packages": [{"name": package, "folder": f"common/{package}"} for package in common],
        "components": [{"name": component, "folder": f"components/{component}", "runs_on": "dev",
                        "entrypoint": entrypoints[component]} for component in workspaces],
    }
    (root / "robot.yaml").write_text(yaml.safe_dump(robot, sort_keys=False))
    return root


@pytest.fixture(scope="module")
def project(docker_client: Any, tmp_path_factory: pytest.TempPathFactory, run_robocore: RobocoreCli) -> Iterator[Path]:
    """The project after prepare-base, stage and a first build (timed)."""
    root = _make_project(tmp_path_factory.mktemp("cmake"))
    run_robocore(root, "prepare-base", "--quiet", timeout=STEP_TIMEOUT)
    _timed(run_robocore, "stage (3 images; 2 with the CMake tool chain)", root, "stage")
    first = _timed(run_robocore, "first build (2 interface packages compiled side by side)", root, "build")
    assert sorted(_built(first)["server"]) == ["demo_interfaces", "demo_server"], first
    yield root
    print("\nmeasured: " + "; ".join(f"{k}: {v:.1f} s" for k, v in TIMES.items()), flush=True)


@pytest.fixture(scope="module")
def robot(project: Path) -> Iterator[Any]:
    """The project brought up isolated by the pytest plugin's machinery (no graph node in this process)."""
    from robocore.testing import bring_up

    run = bring_up(project, graph=False)
    yield run
    run.close()


def test_only_images_with_cmake_packages_get_the_tool_chain(project: Path, docker_client: Any) -> None:
    labels = {name: docker_client.images.get(f"{NAME}-{name}:latest").labels for name in WORKSPACES}
    assert labels["server"].get("dev.robocore.toolchain") == "cmake"
    assert labels["client"].get("dev.robocore.toolchain") == "cmake"
    assert "dev.robocore.toolchain" not in labels["observer"]
    assert "dev.robocore.toolchain" not in docker_client.images.get(f"{NAME}-base:latest").labels


def test_the_service_is_answered_and_the_message_heard_across_containers(robot: Any) -> None:
    robot.wait_for_log("server", "greeter ready", timeout=ANSWER_WITHIN)
    assert robot.wait_for_log("client", "answer: hello, client", timeout=ANSWER_WITHIN)
    assert robot.wait_for_log("client", "heard greeting #", timeout=ANSWER_WITHIN).endswith("hello from the greeter")
    robot.wait_for_log("server", "greeted client", timeout=ANSWER_WITHIN)


def test_a_call_from_another_process_is_answered(robot: Any) -> None:
    """Positive control of the next test: the same one-shot call to the offered service."""
    code, out = robot.exec("client", ["python3", "-m", "demo_client.call", "/greet", "20"])
    assert code == 0 and "answer: hello, once" in out, out


def test_a_service_nobody_offers_is_not_answered(robot: Any) -> None:
    code, out = robot.exec("client", ["python3", "-m", "demo_client.call", "/nobody_offers_this", "3"])
    assert code == 1 and "no service /nobody_offers_this within 3 s" in out, out


def test_without_the_interface_package_the_type_cannot_be_imported(robot: Any) -> None:
    """The observer's install tree holds the same client package but not demo_interfaces; its image has no
    compiler either."""
    code, out = robot.exec("observer", ["python3", "-m", "demo_client.call", "/greet", "3"])
    assert code != 0 and "No module named 'demo_interfaces'" in out, out
    code, out = robot.exec("observer", ["python3", "-c", "import demo_client.client"])
    assert code != 0 and "demo_interfaces" in out, out
    code, out = robot.exec("observer", ["sh", "-c", "command -v cmake || command -v g++ || echo no-compiler"])
    assert out.strip() == "no-compiler", out


def test_no_op_build_and_a_msg_edit_rebuild_only_that_package_and_its_users(project: Path,
                                                                          run_robocore: RobocoreCli) -> None:
    noop = _timed(run_robocore, "no-op build", project, "build")
    assert _built(noop) == {}, noop
    msg = project / "components" / "server" / "src" / "demo_interfaces" / "msg" / "Greeting.msg"
    msg.write_text(msg.read_text() + "# the greeter's count starts at 1\n")
    edited = _timed(run_robocore, "rebuild after a .msg edit (server)", project, "build")
    assert sorted(_built(edited)) == ["server"], edited  # the client's copy did not change
    assert sorted(_built(edited)["server"]) == ["demo_interfaces", "demo_server"], edited
    installed = project / ".robocore" / "build" / "server" / "install" / "demo_interfaces" / "share" / \
        "demo_interfaces" / "msg" / "Greeting.msg"
    assert installed.read_text() == msg.read_text()


def test_a_clean_rebuild_reuses_the_ccache(project: Path, docker_client: Any, run_robocore: RobocoreCli) -> None:
    """ccache's folder outlives the build folder: compiling the client's interfaces again from scratch
    hits it (the server's and the client's copies compiled at the same container paths)."""
    cache = project / ".robocore" / "ccache" / "amd64"  # per arch (robocore.plan.arches)
    assert any(cache.rglob("*")), "the first build left nothing in ccache's folder"
    before = _ccache_hits(docker_client, cache)
    shutil.rmtree(project / ".robocore" / "build" / "client")
    clean = _timed(run_robocore, "clean rebuild of the client (warm ccache)", project, "build", "--component", "client")
    assert sorted(_built(clean)["client"]) == ["demo_client", "demo_interfaces"], clean
    after = _ccache_hits(docker_client, cache)
    assert after > before, f"no ccache hits: {before} before, {after} after"


def _ccache_hits(client: Any, cache: Path) -> int:
    """Cache hits recorded in ``cache`` (ccache --print-stats, read in the client's image)."""
    out = client.containers.run(f"{NAME}-client:latest", ["ccache", "--print-stats"], remove=True,
                                environment={"CCACHE_DIR": "/ccache"}, volumes={str(cache): {"bind": "/ccache"}},
                                user=f"{os.getuid()}:{os.getgid()}").decode()
    stats = dict(line.split("\t", 1) for line in out.splitlines() if "\t" in line)
    return int(stats.get("direct_cache_hit", 0)) + int(stats.get("preprocessed_cache_hit", 0))



@pytest.mark.parametrize("distro", ["jazzy", "kilted"])
def test_an_interface_package_in_common_packages_serves_every_component(
        distro: str, docker_client: Any, tmp_path_factory: pytest.TempPathFactory, run_robocore: RobocoreCli,
        robot_run: Callable[..., Any]) -> None:
    """Built once into the base (which then has the tool chain); the components' workspaces hold only
    their rclpy packages. Kilted's tool set is checked here too."""
    name = f"{NAME}-common-{distro}"
    root = _make_project(tmp_path_factory.mktemp("cmake-common"), name,
                         {"server": ("demo_server",), "client": ("demo_client",)}, common=("demo_interfaces",),
                         distro=distro)
    _timed(run_robocore, f"prepare-base with a common interface package ({distro})", root, "prepare-base")
    run_robocore(root, "stage", "--quiet", timeout=STEP_TIMEOUT)
    run_robocore(root, "build", "--quiet", timeout=STEP_TIMEOUT)
    assert docker_client.images.get(f"{name}-base:latest").labels.get("dev.robocore.toolchain") == "cmake"
    installed = root / ".robocore" / "build" / "client" / "install"
    assert not (installed / "demo_interfaces").exists()  # it comes from the base, not the workspace
    run = robot_run(root, graph=False)
    assert run.wait_for_log("client", "answer: hello, client", timeout=ANSWER_WITHIN)
    assert run.wait_for_log("client", "heard greeting #", timeout=ANSWER_WITHIN)
