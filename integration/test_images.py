"""prepare-base, stage and build against a real Docker daemon, with real rclpy nodes.

The session's ``demo_project`` (conftest) is the template project on the wheels base, taken
from zero (nothing pullable: the Debian root image is bootstrapped) through prepare-base, stage
and build. These tests prove what came out of it.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shlex
import socket
import subprocess
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import lanes
import pytest
from deploy_helpers import free_tcp_port, wait_for

from robocore.config.model import Component
from robocore.plan import naming
from robocore.project import Project

if TYPE_CHECKING:
    from conftest import Restorer, RobocoreCli

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


def test_talker_and_listener_exchange_messages(docker_client: Any, demo_project: Path,
                                               tracked_containers: list[Any]) -> None:
    containers = tracked_containers
    project = _project(demo_project)
    talker, listener = _role(project, "talker"), _role(project, "listener")
    assert talker.entrypoint and listener.entrypoint
    domain, other = lanes.new_domain(), lanes.new_domain()  # suites share the host network: domains of our own
    containers.append(_start(docker_client, project, talker, shlex.split(talker.entrypoint), domain))
    containers.append(_start(docker_client, project, listener, shlex.split(listener.entrypoint), domain))
    # negative control: the same listener on another domain must hear nothing
    containers.append(_start(docker_client, project, listener, shlex.split(listener.entrypoint), other))
    graph = None
    deadline = time.monotonic() + 60
    heard: set[str] = set()
    while time.monotonic() < deadline:
        time.sleep(2)
        published = _quoted(_logs(containers[0]))
        heard = published & _quoted(_logs(containers[1]))
        if heard:
            # the ros2 command of the image sees the running nodes (a graph query over DDS); a new participant
            # on a loaded machine may not have discovered every node and topic within one spin: ask again
            graph = docker_client.containers.run(
                _image(project, listener),
                ["bash", "-c", "ros2 node list --no-daemon --spin-time 3 && ros2 topic list --no-daemon --spin-time 3"],
                network_mode="host", ipc_mode="host", environment={"ROS_DOMAIN_ID": str(domain)}, remove=True,
                name=f"{PREFIX}-graph-{uuid.uuid4().hex[:8]}",
            ).decode()
            if all(name in graph for name in ("/talker", "/listener", "/chatter")):
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


def test_second_prepare_base_and_stage_are_no_ops(docker_client: Any, demo_project: Path,
                                                  run_robocore: RobocoreCli) -> None:
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


def test_noop_build_then_one_edit_rebuilds_only_that_package(demo_project: Path, run_robocore: RobocoreCli) -> None:
    project = _project(demo_project)
    result = json.loads(run_robocore(demo_project, "build", "--json").stdout)
    # the message names each component's action and reason (e.g. "image changed": a staged image re-tagged)
    assert {r["action"] for r in result["results"]} == {"up-to-date"}, \
        {r["what"]: (r["action"], r.get("reason")) for r in result["results"]}
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


def _talker_says(client: Any, project: Project, comp: Component, needle: str, started: list[Any],
                 timeout: float = 30) -> str:
    """Start the talker from its install tree (its container goes into ``started``, tracked_containers); return
    its output once it prints ``needle`` or exits (or after ``timeout`` seconds)."""
    assert comp.entrypoint
    container = _start(client, project, comp, shlex.split(comp.entrypoint), lanes.new_domain())
    started.append(container)

    def said() -> str | None:
        out = _logs(container)
        container.reload()
        return out if needle in out or container.status == "exited" else None

    return wait_for(said, timeout) or _logs(container)


def test_module_edit_is_copied_without_colcon_and_runs_but_a_new_module_needs_colcon(
        docker_client: Any, demo_project: Path, run_robocore: RobocoreCli, restore: Restorer,
        tracked_containers: list[Any]) -> None:
    """The fast path writes the edited module into the install tree and the node runs it; adding a
    module (which only colcon can install) goes through colcon: the negative control."""
    project = _project(demo_project)
    talker = _role(project, "talker")
    assert talker.folder
    module = next(p for p in (demo_project / talker.folder).rglob("talker.py"))
    extra = module.parent / "robocore_it_extra.py"
    restore.keep(module, extra)  # then the shared project is built again from its own sources
    restore.then(lambda: run_robocore(demo_project, "build", "--component", talker.name))
    original = module.read_text()
    token = uuid.uuid4().hex[:8]
    module.write_text(original.replace('f"hello from talker #', f'f"patched {token} #'))
    assert module.read_text() != original
    result = json.loads(run_robocore(demo_project, "build", "--component", talker.name, "--json").stdout)
    (row,) = result["results"]
    assert row["action"] == "built" and "no colcon" in row["reason"], row
    out = _talker_says(docker_client, project, talker, f"patched {token}", tracked_containers)
    assert f"patched {token} #" in out, out[-1500:]

    extra.write_text(f"WORD = 'extra {token}'\n")
    module.write_text(module.read_text().replace(
        "import rclpy\n", "import rclpy\n\nfrom .robocore_it_extra import WORD\n", 1).replace(
        f'f"patched {token} #', 'f"{WORD} #'))
    result = json.loads(run_robocore(demo_project, "build", "--component", talker.name, "--json").stdout)
    (row,) = result["results"]
    assert row["action"] == "built" and "colcon: " in row["reason"] and "file added" in row["reason"], row
    out = _talker_says(docker_client, project, talker, f"extra {token}", tracked_containers)
    assert f"extra {token} #" in out, out[-1500:]


def test_failed_build_names_the_package_and_shows_its_log(demo_project: Path, run_robocore: RobocoreCli,
                                                          restore: Restorer) -> None:
    project = _project(demo_project)
    listener = _role(project, "listener")
    assert listener.folder
    broken = demo_project / listener.folder / "robocore_it_broken"
    restore.keep(broken)  # then the shared project builds again without it
    restore.then(lambda: run_robocore(demo_project, "build", "--component", listener.name))
    broken.mkdir(parents=True)
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


def test_dry_run_prints_the_plan(demo_project: Path, run_robocore: RobocoreCli) -> None:
    out = run_robocore(demo_project, "stage", "--dry-run").stdout
    # a dry run asks no daemon, so whether the images are up to date is unknown, and said so
    assert "FROM " in out and "build or keep: unknown (dry run: not contacted)" in out


# ------------------------------------------------------------------ common packages, repositories, pip


def _ament_python_pkg(folder: Path, name: str, module_text: str) -> None:
    (folder / name).mkdir(parents=True, exist_ok=True)
    (folder / "resource").mkdir(exist_ok=True)
    (folder / "resource" / name).write_text("")
    (folder / name / "__init__.py").write_text(module_text)
    (folder / "package.xml").write_text(
        f'<?xml version="1.0"?>\n<package format="3"><name>{name}</name><version>0.1.0</version>'
        f"<description>test</description><maintainer email=\"dev@example.com\">dev</maintainer>"
        f"<license>Apache-2.0</license><export><build_type>ament_python</build_type></export></package>\n")
    (folder / "setup.py").write_text(
        "from setuptools import setup\n"
        f"setup(name='{name}', version='0.1.0', packages=['{name}'], data_files=["
        f"('share/ament_index/resource_index/packages', ['resource/{name}']), ('share/{name}', ['package.xml'])])\n")


def _git_daemon(base: Path) -> tuple[subprocess.Popen[bytes], int]:
    """``git daemon`` serving the repositories under ``base`` on a free loopback port (git:// is a network
    transport: robocore fetches it without robot.yaml's opt-in to local repositories)."""
    port = free_tcp_port()
    proc = subprocess.Popen(["git", "daemon", "--export-all", f"--base-path={base}", "--listen=127.0.0.1",
                             f"--port={port}", "--reuseaddr", str(base)], stderr=subprocess.DEVNULL)

    def listening() -> bool:
        with socket.socket() as client, contextlib.suppress(OSError):
            client.connect(("127.0.0.1", port))
            return True
        return False

    if wait_for(listening, 10, interval=0.1):
        return proc, port
    proc.kill()
    raise RuntimeError("git daemon did not start")


@pytest.fixture(scope="module")
def deps_project(docker_client: Any, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """A wheels project with a common package, a component with a git repository and pip packages."""
    import yaml

    root = tmp_path_factory.mktemp("deps") / "robocore-it-deps"
    upstream = root.parent / "upstream-repo"
    _ament_python_pkg(upstream, "it_dep_util", "VALUE = 'from a repository'\n")
    for args in (["init", "-q", "-b", "main"], ["add", "-A"],
                 ["-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "-m", "init"]):
        subprocess.run(["git", *args], cwd=upstream, check=True, capture_output=True)
    daemon, port = _git_daemon(root.parent)
    # plain git:// (unencrypted) needs robot.yaml's opt-in
    repository = {"url": f"git://127.0.0.1:{port}/{upstream.name}", "version": "main", "allow_protocol": "git"}
    _ament_python_pkg(root / "common" / "it_common_util", "it_common_util", "VALUE = 'from common'\n")
    for comp in ("alpha", "beta"):
        _ament_python_pkg(root / "components" / comp / "src" / f"it_{comp}_code", f"it_{comp}_code", "SECRET = 1\n")
    robot = {
        "ros_distro": "jazzy", "base": {"kind": "wheels"},
        "hosts": [{"name": "devmachine", "ip": "127.0.0.1"}],
        "common_packages": [{"name": "it_common_util", "folder": "common/it_common_util"}],
        "components": [
            {"name": "alpha", "runs_on": "devmachine", "folder": "components/alpha",
             "repositories": [repository],
             "postinstall": ["python -c 'import it_dep_util' && touch /etc/alpha-postinstall-ran"]},
            {"name": "beta", "runs_on": "devmachine", "folder": "components/beta", "pip_packages": ["six"]},
        ],
    }
    (root / "robot.yaml").write_text(yaml.safe_dump(robot, sort_keys=False))
    yield root
    daemon.terminate()
    daemon.wait(timeout=10)


def test_common_packages_repositories_and_pip_are_in_the_images(
        docker_client: Any, deps_project: Path, run_robocore: RobocoreCli) -> None:
    run_robocore(deps_project, "prepare-base", "--quiet")
    run_robocore(deps_project, "stage", "--quiet")
    project = _project(deps_project)
    alpha, beta = (f"{naming.component_image(project.robot, project.name, c)}:latest" for c in ("alpha", "beta"))
    script = ("set -e; ros2 pkg list | grep -x {pkg}; python -c 'import {mods}; print(\"imports-ok\")'; "
              "test ! -e /robocore/ws && ! find / -xdev -path /proc -prune -o -name 'it_*_code*' -print | grep -q . "
              "&& echo no-user-code")
    out = docker_client.containers.run(
        alpha, ["bash", "-c", script.format(pkg="it_dep_util", mods="it_common_util, it_dep_util")
                + "; test -e /etc/alpha-postinstall-ran && echo postinstall-ok"],
        remove=True, name=f"{PREFIX}-deps-{uuid.uuid4().hex[:8]}").decode()
    assert "it_dep_util" in out and "imports-ok" in out and "no-user-code" in out and "postinstall-ok" in out, out
    out = docker_client.containers.run(
        beta, ["bash", "-c", script.format(pkg="it_common_util", mods="it_common_util, six")],
        remove=True, name=f"{PREFIX}-deps-{uuid.uuid4().hex[:8]}").decode()
    assert "imports-ok" in out and "no-user-code" in out, out
    # a negative control for the import probe: a module that is not installed fails
    probe = docker_client.containers.run(beta, ["bash", "-c", "python -c 'import it_dep_util' || echo missing"],
                                         remove=True, name=f"{PREFIX}-deps-{uuid.uuid4().hex[:8]}").decode()
    assert "missing" in probe


def test_changing_one_components_packages_restages_only_that_one(
        docker_client: Any, deps_project: Path, run_robocore: RobocoreCli) -> None:
    import yaml

    run_robocore(deps_project, "prepare-base", "--quiet")
    run_robocore(deps_project, "stage", "--quiet")
    project = _project(deps_project)
    before = _image_ids(docker_client, project)
    data = yaml.safe_load((deps_project / "robot.yaml").read_text())
    data["components"][1]["pip_packages"] = ["six", "idna"]
    (deps_project / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    result = json.loads(run_robocore(deps_project, "stage", "--json").stdout)
    actions = {r["what"].split(":")[0].rsplit("-", 1)[-1]: r["action"] for r in result["results"]}
    assert actions == {"alpha": "up-to-date", "beta": "built"}, result
    after = _image_ids(docker_client, _project(deps_project))
    changed = {ref for ref in before if before[ref] != after[ref]}
    assert changed == {f"{naming.component_image(project.robot, project.name, 'beta')}:latest"}


def test_build_runs_as_the_invoking_user_even_when_that_is_not_root(
        demo_project: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """As root, pretend to be UID 4242 (owning a copy of the project): the build's files must be 4242's."""
    import shutil

    from robocore.commands import build
    from robocore.commands.support.context import Options
    from robocore.plan import arches
    from robocore.project import BUILD_STATE

    uid = os.getuid()
    copy = tmp_path / demo_project.name  # same folder name: same project name, same staged images
    shutil.copytree(demo_project, copy, ignore=shutil.ignore_patterns("build"))
    listener = _role(_project(copy), "listener")
    if uid == 0:
        uid = 4242
        for sub in ("build", "install", "log"):  # what robocore, running as 4242, would have created
            (copy / ".robocore" / "build" / listener.name / sub).mkdir(parents=True)
        for path in [copy, *copy.rglob("*")]:
            os.lchown(path, uid, uid)
        monkeypatch.setattr(os, "getuid", lambda: uid)
        monkeypatch.setattr(os, "getgid", lambda: uid)
    build.build(Options(project_dir=copy, quiet=True), component=listener.name)
    own = {BUILD_STATE, arches.INSTALL_ARCH_FILE}  # written by robocore itself (here root pretending), not colcon
    produced = [p for p in (copy / ".robocore" / "build" / listener.name).rglob("*")
                if not p.is_symlink() and p.name not in own]
    assert any(p.name == "setup.bash" for p in produced)
    wrong = [str(p) for p in produced if p.stat().st_uid != uid]
    assert not wrong, f"files in .robocore/build not owned by the invoking user: {wrong[:5]}"
