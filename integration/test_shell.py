"""``robocore shell`` against a real Docker daemon and a real X server (Xvfb).

Each test makes its own small project whose components use a test image (Debian 12 with
x11-utils, sudo and a user ``ubuntu`` at UID 1000, like Ubuntu 24.04 images) or the plain
Debian root image (no sudo). The developer's UID is simulated with ``ROBOCORE_UID`` so
that the "image already has a user at that UID" path is exercised even when CI runs as root.
Negative controls: a wrong X cookie is refused; a root-made file is root-owned; a ``--new``
container does not see the first container's files.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib
import io
import os
import secrets
import shutil
import socket
import subprocess
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
from deploy_helpers import project_containers, wait_for

from robocore.plan import naming

if TYPE_CHECKING:
    from conftest import Env, RobocoreCli

pytestmark = pytest.mark.docker

PREFIX = "robocore-it-shell"
TEST_IMAGE = f"{PREFIX}-x11:latest"
ROOT_CANDIDATES = ("robocore/amd64/debian:bookworm-wheels", "debian:bookworm", "robocore-test/debian:bookworm")
DOCKERFILE = """\
FROM {root}
RUN apt-get update \\
 && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends x11-utils sudo \\
 && rm -rf /var/lib/apt/lists/* \\
 && useradd -u 1000 -m -s /bin/bash ubuntu
"""
INPUTS_LABEL = "dev.robocore.test-inputs"


# --- images ------------------------------------------------------------------------------


def _root_image(client: Any) -> str:
    from docker.errors import ImageNotFound

    for ref in ROOT_CANDIDATES:
        try:
            client.images.get(ref)
            return ref
        except ImageNotFound:
            continue
    rootfs = importlib.import_module("robocore.adapters.rootfs")  # bootstraps Debian 12 with mmdebstrap
    from robocore.config.model import BaseKind
    from robocore.plan import arches, dockerfiles

    with tempfile.TemporaryDirectory(prefix=f"{PREFIX}-") as work:
        ref, _ = rootfs.ensure_root_image(
            client, target=ROOT_CANDIDATES[0], upstream="debian:bookworm", arch="amd64",
            strap=arches.root_strap(BaseKind.wheels, "amd64", dockerfiles.WHEELS_APT), work_dir=Path(work),
            status=print)
    return str(ref)


@pytest.fixture(scope="session")
def root_image(docker_client: Any) -> str:
    """A Debian 12 image without sudo and without a user at UID 1000."""
    return _root_image(docker_client)


@pytest.fixture(scope="session")
def shell_image(docker_client: Any, root_image: str) -> str:
    """The X11 test image; rebuilt only when its Dockerfile or root image changed (kept as a cache)."""
    from docker.errors import ImageNotFound

    text = DOCKERFILE.format(root=root_image)
    inputs = hashlib.sha256((text + docker_client.images.get(root_image).id).encode()).hexdigest()[:16]
    try:
        if docker_client.images.get(TEST_IMAGE).labels.get(INPUTS_LABEL) == inputs:
            return TEST_IMAGE
    except ImageNotFound:
        pass
    docker_client.images.build(fileobj=io.BytesIO(text.encode()), tag=TEST_IMAGE, rm=True, forcerm=True,
                               labels={INPUTS_LABEL: inputs})
    return TEST_IMAGE


# --- projects ----------------------------------------------------------------------------


def _containers(client: Any, project: str) -> list[Any]:
    return project_containers(client, project)


@pytest.fixture
def project(docker_client: Any, shell_image: str, root_image: str) -> Iterator[Path]:
    """A project with ``ws`` (staged-image stand-in: the X11 image) and ``bare`` (image: Debian, no sudo)."""
    name = f"{PREFIX}-{secrets.token_hex(3)}"
    parent = Path(tempfile.mkdtemp(prefix=f"{PREFIX}-"))
    root = parent / name
    (root / "ws" / "src").mkdir(parents=True)
    os.chmod(root / "ws", 0o777)  # a simulated developer (ROBOCORE_UID) must be able to write it
    prefix = f"{name}-img-"
    (root / "robot.yaml").write_text(
        f"ros_distro: jazzy\nimage_prefix: \"{prefix}\"\n"
        "hosts:\n  - name: dev\n    ip: 127.0.0.1\n"
        "components:\n"
        "  - name: ws\n    runs_on: dev\n    folder: ws\n"
        f"  - name: bare\n    runs_on: dev\n    image: \"{root_image}\"\n"
    )
    staged = f"{prefix}ws"
    docker_client.images.get(shell_image).tag(staged, "latest")
    try:
        yield root
    finally:
        for container in _containers(docker_client, name):
            container.remove(force=True)
        docker_client.images.remove(f"{staged}:latest", noprune=True)
        shutil.rmtree(parent, ignore_errors=True)


#: The developer's display, removed from the CLI's environment unless a test gives one.
NO_DISPLAY: dict[str, str | None] = {"DISPLAY": None, "WAYLAND_DISPLAY": None, "XAUTHORITY": None}


class Shell:
    """``robocore shell`` through conftest's ``run_robocore``, with no display unless a test gives one."""

    def __init__(self, cli: RobocoreCli) -> None:
        self.cli = cli

    def __call__(self, project: Path, component: str, cmd: str, *extra: str, env: Env | None = None,
                 check: bool = False) -> subprocess.CompletedProcess[str]:
        """``shell --component COMPONENT --cmd CMD EXTRA`` to its end (``check``: must exit 0)."""
        return self.cli(project, "shell", "--component", component, "--cmd", cmd, *extra,
                        env={**NO_DISPLAY, **(env or {})}, check=check, timeout=180)

    def background(self, project: Path, component: str, cmd: str) -> subprocess.Popen[str]:
        """``shell --cmd`` left running (no DISPLAY), for tests that join or change it meanwhile."""
        return self.cli.start(project, "shell", "--component", component, "--cmd", cmd, env={"DISPLAY": None})


@pytest.fixture(scope="session")
def shell(run_robocore: RobocoreCli) -> Shell:
    """``shell(project, component, cmd, *extra, env=None, check=False)`` and ``shell.background(...)``."""
    return Shell(run_robocore)


# --- X server ----------------------------------------------------------------------------


class Display:
    def __init__(self, number: int, auth: Path) -> None:
        self.name = f":{number}"
        self.auth = auth


@pytest.fixture
def xvfb(tmp_path: Path) -> Iterator[Display]:
    """A real Xvfb that only accepts clients holding its MIT-MAGIC-COOKIE (``-auth FILE``)."""
    number = next(n for n in range(140, 400)
                  if not Path(f"/tmp/.X11-unix/X{n}").exists() and not Path(f"/tmp/.X{n}-lock").exists())
    auth = tmp_path / "host.xauth"
    subprocess.run(["xauth", "-q", "-f", str(auth), "add", f":{number}", ".", secrets.token_hex(16)], check=True)
    server = subprocess.Popen(["Xvfb", f":{number}", "-auth", str(auth), "-nolisten", "tcp",
                               "-screen", "0", "1234x567x24"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    socket_file = Path(f"/tmp/.X11-unix/X{number}")
    wait_for(lambda: socket_file.exists() or server.poll() is not None, 20, interval=0.05)
    if not socket_file.exists():
        server.kill()
        pytest.fail(f"Xvfb :{number} did not start: {server.stderr.read().decode() if server.stderr else ''}")
    try:
        yield Display(number, auth)
    finally:
        server.terminate()
        server.wait(timeout=10)


def _wait_for_file(client: Any, container: str, path: str, session: subprocess.Popen[str]) -> None:
    """Wait (asking Docker directly, not through another shell) until ``path`` exists in ``container``."""
    from docker.errors import APIError, NotFound

    def exists() -> bool:
        try:
            if client.containers.get(container).exec_run(["test", "-e", path]).exit_code == 0:
                return True
        except (NotFound, APIError):
            pass
        assert session.poll() is None, session.communicate()
        return False

    assert wait_for(exists, 60, interval=0.1), f"{path} never appeared in {container}"


# --- tests -------------------------------------------------------------------------------


def test_x_client_reaches_the_display_with_the_cookie_and_is_refused_without(project: Path, xvfb: Display,
                                                                            tmp_path: Path, shell: Shell) -> None:
    env = {"DISPLAY": xvfb.name, "XAUTHORITY": str(xvfb.auth), "USER": "alice"}
    if os.getuid() == 0:  # CI runs as root: be a UID 1000 developer (robocore hands the cookie file to that UID)
        env["ROBOCORE_UID"] = "1000"
    out = shell(project, "ws", "xdpyinfo | grep -E 'name of display|dimensions'", env=env, check=True).stdout
    assert f"name of display:    {xvfb.name}" in out
    assert "1234x567 pixels" in out  # the Xvfb this test started, not another display

    # negative control: a cookie the server does not know is refused
    wrong = tmp_path / "wrong.xauth"
    subprocess.run(["xauth", "-q", "-f", str(wrong), "add", xvfb.name, ".", secrets.token_hex(16)], check=True)
    refused = shell(project, "ws", "xdpyinfo", env={**env, "XAUTHORITY": str(wrong)})
    assert refused.returncode != 0
    assert "unable to open display" in refused.stderr
    # and without any display the shell is quietly headless
    headless = shell(project, "ws", "echo \"[$DISPLAY]\"; ls /robocore", env={"ROBOCORE_UID": "1000"}, check=True)
    assert headless.stdout.splitlines()[0] == "[]"
    assert "x11" not in headless.stdout.split()
    assert "xauth" not in headless.stderr and "DISPLAY" not in headless.stderr


@pytest.mark.parametrize(
    ("uid", "user", "expected_name"),
    [
        (None, None, None),  # whoever runs the tests (root in CI)
        (1000, "alice", "alice"),  # the image already has `ubuntu` at 1000: renamed
        (4242, "bob", "bob"),  # a new user
        (1500, "ubuntu", "ubuntu"),  # the name exists with another UID: it gets the developer's UID
    ],
)
def test_files_made_in_the_shell_belong_to_the_developer(project: Path, uid: int | None, user: str | None,
                                                          expected_name: str | None, shell: Shell) -> None:
    env: dict[str, str] = {}
    if uid is not None:
        env["ROBOCORE_UID"] = str(uid)
    if user is not None:
        env["USER"] = user
    want_uid = os.getuid() if uid is None else uid
    out = shell(project, "ws", "touch mine && sudo -n touch by-sudo && id -un && id -u && pwd && echo $HOME "
                "&& sudo -n id -u && id -Gn | tr ' ' ,", env=env, check=True).stdout.split()
    name, seen_uid, cwd, home, sudo_uid, groups = out[:6]
    assert int(seen_uid) == want_uid
    if expected_name is not None:
        assert name == expected_name
    assert cwd == naming.CONTAINER_WS
    assert home == f"/home/{name}"
    assert sudo_uid == "0"  # passwordless sudo
    if want_uid:
        assert {"dialout", "video"} <= set(groups.split(","))  # hardware groups of the image
    assert (project / "ws" / "mine").stat().st_uid == want_uid
    assert (project / "ws" / "mine").stat().st_gid == want_uid  # ROBOCORE_GID defaults to the UID
    # negative control: what root makes is root's, so the check above can tell them apart
    assert (project / "ws" / "by-sudo").stat().st_uid == 0
    assert (project / ".robocore" / "home" / name).stat().st_uid == want_uid


def test_image_without_sudo_still_gets_the_user(project: Path, shell: Shell) -> None:
    out = shell(project, "bare", "id -un; id -u; pwd; test -e /run/robocore/no-sudo && echo no-sudo",
                env={"ROBOCORE_UID": "1000", "USER": "alice"}, check=True).stdout.split()
    assert out == ["alice", "1000", "/home/alice", "no-sudo"]


def test_second_shell_joins_the_first_and_new_starts_another(project: Path, docker_client: Any,
                                                             shell: Shell) -> None:
    name = project.name
    first = shell.background(
        project, "ws", "echo here > /tmp/first-was-here; while [ ! -e /tmp/stop ]; do sleep 0.1; done; echo first-done")
    container_name = naming.shell_container_name(name, "ws")
    _wait_for_file(docker_client, container_name, "/tmp/first-was-here", first)
    first_id = docker_client.containers.get(container_name).id

    joined = shell(project, "ws", "cat /tmp/first-was-here", check=True).stdout
    assert joined.strip() == "here"  # /tmp is private to the container: same container
    assert docker_client.containers.get(container_name).id == first_id
    assert [c.name for c in _containers(docker_client, name)] == [container_name]

    # negative control: --new is another container, which has no such file
    other = shell(project, "ws", "echo $ROBOCORE_CONTAINER; cat /tmp/first-was-here", "--new")
    assert other.returncode != 0
    assert other.stdout.split()[0] == naming.shell_container_name(name, "ws", 1)
    assert docker_client.containers.get(container_name).id == first_id

    shell(project, "ws", "touch /tmp/stop", check=True)
    stdout, stderr = first.communicate(timeout=60)
    assert first.returncode == 0, stderr
    assert "first-done" in stdout
    # the last session left: no dev container is left behind
    assert _containers(docker_client, name) == []


def test_spec_change_is_reported_when_joining(project: Path, docker_client: Any, shell: Shell) -> None:
    first = shell.background(project, "ws", "while [ ! -e /tmp/stop ]; do sleep 0.1; done")
    _wait_for_file(docker_client, naming.shell_container_name(project.name, "ws"), "/run/robocore/ready", first)
    same = shell(project, "ws", "true")
    assert "differs" not in same.stderr  # negative control: same spec, no note
    changed = shell(project, "ws", "touch /tmp/stop", "--devices", "all", check=True)
    assert changed.stdout == ""
    assert "differs" in changed.stderr and "--new" in changed.stderr
    first.communicate(timeout=60)


def test_interactive_login_shell_has_prompt_aliases_and_persistent_history(project: Path, shell: Shell,
                                                                            run_robocore: RobocoreCli) -> None:
    typed = "alias topic cb\necho \"PS1=$PS1\"\necho marker-$((6*7))\nexit 7\n"
    env = {"DISPLAY": None, "ROBOCORE_UID": "1000", "USER": "alice", "TERM": "dumb"}
    done = run_robocore.in_terminal(project, "shell", "--component", "ws", typed=typed, env=env, timeout=120)
    assert done.returncode == 7, done.stdout
    assert "alias topic='ros2 topic'" in done.stdout
    assert "marker-42" in done.stdout
    assert f"[{naming.shell_container_name(project.name, 'ws')}]" in done.stdout  # the rendered prompt
    history = (project / ".robocore" / "home" / "alice" / ".bash_history").read_text()
    assert "echo marker-$((6*7))" in history
    # a later container (the first was removed) has the same home
    assert shell(project, "ws", "tail -n 2 ~/.bash_history", env={"ROBOCORE_UID": "1000", "USER": "alice"},
                 check=True).stdout


def test_cmd_gets_a_terminal_when_robocore_has_one(project: Path, shell: Shell, run_robocore: RobocoreCli) -> None:
    """``shell --cmd tmux`` needs a TTY: given when robocore runs on a terminal, not when its output is captured."""
    on_terminal = run_robocore.in_terminal(project, "shell", "--component", "ws", "--cmd",
                                           "tty || true; echo term=$TERM", typed="",
                                           env={"DISPLAY": None, "TERM": "xterm"}, timeout=120)
    assert on_terminal.returncode == 0, on_terminal.stdout
    assert "/dev/pts/" in on_terminal.stdout and "term=xterm" in on_terminal.stdout, on_terminal.stdout
    # negative control: the same command with robocore's output captured gets no terminal
    captured = shell(project, "ws", "tty || true", check=True).stdout
    assert "not a tty" in captured and "/dev/pts/" not in captured


def test_staged_image_sources_ros_and_the_install_tree(demo_project: Path, shell: Shell) -> None:
    """The template project after stage+build: ROS, the install tree and a SUPER_CLIENT DDS setup."""
    from robocore.project import Project

    proj = Project.load(demo_project)
    comp = next(c for c in proj.robot.components if c.folder)
    packages = sorted(p.parent.name for p in (demo_project / str(comp.folder)).rglob("package.xml"))
    assert packages
    build_dir = demo_project / ".robocore" / "build" / comp.name
    stamp = time.time()
    out = shell(demo_project, comp.name,
                "python3 -c 'import rclpy; print(\"rclpy-ok\")'; echo \"super=$ROS_SUPER_CLIENT\"; "
                "echo \"ament=$AMENT_PREFIX_PATH\"; "
                "cd /tmp && colcon build >/dev/null && echo built", check=True).stdout
    assert "rclpy-ok" in out
    assert "super=TRUE" in out
    assert f"{naming.CONTAINER_INSTALL}/" in out.split("ament=", 1)[1].splitlines()[0]
    assert "built" in out.split()
    # colcon's defaults put a build started anywhere into robocore's folders, not the source tree
    assert (build_dir / "install" / packages[0]).is_dir()
    assert (build_dir / "log" / "latest_build").resolve().stat().st_mtime >= stamp - 1
    for stray in ("build", "install", "log"):
        assert not (demo_project / str(comp.folder) / stray).exists()


def _host_device() -> str:
    """A character device of the host that Docker's default /dev does not have and root may open."""
    for path in ("/dev/cpu_dma_latency", "/dev/loop-control", "/dev/fuse"):
        if Path(path).is_char_device():
            return path
    pytest.fail("none of /dev/cpu_dma_latency, /dev/loop-control, /dev/fuse exists on this host")


def test_devices_from_the_component_and_devices_all(project: Path, shell: Shell) -> None:
    device = _host_device()
    probe = f"sudo -n sh -c 'exec 3<{device} && echo opened' 2>&1 || true; test -e {device} || echo absent"
    # negative control: by default the device is not there
    default = shell(project, "ws", probe, check=True).stdout.split()
    assert "absent" in default and "opened" not in default
    # --devices all: the whole /dev, and the device cgroup lets it be opened
    assert "opened" in shell(project, "ws", probe, "--devices", "all", check=True).stdout.split()
    # a component's devices: list
    with (project / "robot.yaml").open("a") as handle:
        handle.write(f"  - name: hw\n    runs_on: dev\n    image: \"{TEST_IMAGE}\"\n    devices: [\"{device}\"]\n")
    assert "opened" in shell(project, "hw", probe, check=True).stdout.split()


@pytest.fixture
def compositor() -> Iterator[Path]:
    """A stand-in Wayland compositor: a socket in a runtime folder of its own that answers its first client with
    ``hello-from-the-compositor``; closed and removed when the test ends."""
    runtime = Path(tempfile.mkdtemp(prefix="rc-xdg-"))  # short: AF_UNIX paths are limited to 107 bytes
    path = runtime / "wayland-robocore-test"
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(str(path))
    os.chmod(path, 0o777)  # a compositor's socket belongs to the developer; the test may be root
    server.listen(1)

    def answer() -> None:
        with contextlib.suppress(OSError):  # closed before anyone came
            conn, _ = server.accept()
            with conn:
                conn.sendall(b"hello-from-the-compositor")

    threading.Thread(target=answer, daemon=True).start()
    yield path
    server.close()
    shutil.rmtree(runtime, ignore_errors=True)


def test_wayland_socket_reaches_the_container(project: Path, compositor: Path, shell: Shell) -> None:
    env = {"XDG_RUNTIME_DIR": str(compositor.parent), "WAYLAND_DISPLAY": compositor.name, "ROBOCORE_UID": "1000",
           "USER": "alice"}
    connect = ("python3 -c \"import os, socket; s = socket.socket(socket.AF_UNIX); "
               "s.connect(os.path.join(os.environ['XDG_RUNTIME_DIR'], os.environ['WAYLAND_DISPLAY'])); "
               "print(s.recv(100).decode())\"; stat -c %a:%u \"$XDG_RUNTIME_DIR\"")
    out = shell(project, "ws", connect, env=env, check=True).stdout.split()
    assert out == ["hello-from-the-compositor", "700:1000"]
    # negative control: no WAYLAND_DISPLAY, no socket
    out = shell(project, "ws", "echo \"[$WAYLAND_DISPLAY]\"; test -e /robocore/xdg || echo no-xdg",
                env={"ROBOCORE_UID": "1000"}, check=True).stdout.split()
    assert out == ["[]", "no-xdg"]


def test_a_foreign_container_with_the_shell_name_is_left_alone(project: Path, docker_client: Any, root_image: str,
                                                               shell: Shell, tracked_containers: list[Any]) -> None:
    name = naming.shell_container_name(project.name, "ws")
    foreign = docker_client.containers.run(root_image, ["sleep", "60"], name=name, detach=True,
                                           labels={naming.LABEL_PROJECT: project.name})
    tracked_containers.append(foreign)
    refused = shell(project, "ws", "true")
    assert refused.returncode != 0
    assert "is not a robocore dev shell" in refused.stderr
    foreign.reload()
    assert foreign.status == "running"
