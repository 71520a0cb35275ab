"""``robocore shell`` against a real Docker daemon and a real X server (Xvfb).

Each test makes its own small project whose components use a test image (Debian 12 with
x11-utils, sudo and a user ``ubuntu`` at UID 1000, like Ubuntu 24.04 images) or the plain
Debian root image (no sudo). The developer's UID is simulated with ``ROBOCORE_UID`` so
that the "image already has a user at that UID" path is exercised even when CI runs as root.
Negative controls: a wrong X cookie is refused; a root-made file is root-owned; a ``--new``
container does not see the first container's files.
"""

from __future__ import annotations

import hashlib
import importlib
import io
import os
import secrets
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from robocore.plan import naming

pytestmark = pytest.mark.docker

PREFIX = "robocore-it-shell"
TEST_IMAGE = f"{PREFIX}-x11:latest"
ROOT_CANDIDATES = ("robocore/debian:bookworm", "debian:bookworm", "robocore-test/debian:bookworm")
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
    with tempfile.TemporaryDirectory(prefix=f"{PREFIX}-") as work:
        ref, _ = rootfs.ensure_root_image(client, None, work_dir=Path(work), status=print)
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
    return list(client.containers.list(all=True, filters={"label": f"{naming.LABEL_PROJECT}={project}"}))


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


def robocore(project: Path, *args: str, env: dict[str, str] | None = None, timeout: float = 180,
             stdin: Any = subprocess.DEVNULL) -> subprocess.CompletedProcess[str]:
    """Run ``robocore -p PROJECT ARGS`` with a controlled environment (no display unless given)."""
    full = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "XAUTHORITY")}
    full.update(env or {})
    return subprocess.run([sys.executable, "-m", "robocore", "-p", str(project), *args], env=full,
                          capture_output=True, text=True, timeout=timeout, stdin=stdin)


def shell(project: Path, component: str, cmd: str, *extra: str, env: dict[str, str] | None = None) -> (
        subprocess.CompletedProcess[str]):
    return robocore(project, "shell", "--component", component, "--cmd", cmd, *extra, env=env)


def background_shell(project: Path, component: str, cmd: str) -> subprocess.Popen[str]:
    """``robocore shell --cmd`` left running (no DISPLAY), for tests that join or change it meanwhile."""
    return subprocess.Popen(
        [sys.executable, "-m", "robocore", "-p", str(project), "shell", "--component", component, "--cmd", cmd],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL,
        env={k: v for k, v in os.environ.items() if k != "DISPLAY"},
    )


def ok(proc: subprocess.CompletedProcess[str]) -> str:
    assert proc.returncode == 0, f"exit {proc.returncode}\n--- stdout\n{proc.stdout}\n--- stderr\n{proc.stderr}"
    return proc.stdout


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
    deadline = time.monotonic() + 20
    while not Path(f"/tmp/.X11-unix/X{number}").exists():
        if server.poll() is not None or time.monotonic() > deadline:
            server.kill()
            pytest.fail(f"Xvfb :{number} did not start: {server.stderr.read().decode() if server.stderr else ''}")
        time.sleep(0.05)
    try:
        yield Display(number, auth)
    finally:
        server.terminate()
        server.wait(timeout=10)


def _wait_for_file(client: Any, container: str, path: str, session: subprocess.Popen[str]) -> None:
    """Wait (asking Docker directly, not through another shell) until ``path`` exists in ``container``."""
    from docker.errors import APIError, NotFound

    deadline = time.monotonic() + 60
    while True:
        try:
            if client.containers.get(container).exec_run(["test", "-e", path]).exit_code == 0:
                return
        except (NotFound, APIError):
            pass
        assert session.poll() is None, session.communicate()
        assert time.monotonic() < deadline, f"{path} never appeared in {container}"
        time.sleep(0.1)


# --- tests -------------------------------------------------------------------------------


def test_x_client_reaches_the_display_with_the_cookie_and_is_refused_without(project: Path, xvfb: Display,
                                                                            tmp_path: Path) -> None:
    env = {"DISPLAY": xvfb.name, "XAUTHORITY": str(xvfb.auth), "USER": "alice"}
    if os.getuid() == 0:  # CI runs as root: be a UID 1000 developer (robocore hands the cookie file to that UID)
        env["ROBOCORE_UID"] = "1000"
    out = ok(shell(project, "ws", "xdpyinfo | grep -E 'name of display|dimensions'", env=env))
    assert f"name of display:    {xvfb.name}" in out
    assert "1234x567 pixels" in out  # the Xvfb this test started, not another display

    # negative control: a cookie the server does not know is refused
    wrong = tmp_path / "wrong.xauth"
    subprocess.run(["xauth", "-q", "-f", str(wrong), "add", xvfb.name, ".", secrets.token_hex(16)], check=True)
    refused = shell(project, "ws", "xdpyinfo", env={**env, "XAUTHORITY": str(wrong)})
    assert refused.returncode != 0
    assert "unable to open display" in refused.stderr
    # and without any display the shell is quietly headless
    headless = shell(project, "ws", "echo \"[$DISPLAY]\"; ls /robocore", env={"ROBOCORE_UID": "1000"})
    assert ok(headless).splitlines()[0] == "[]"
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
                                                          expected_name: str | None) -> None:
    env: dict[str, str] = {}
    if uid is not None:
        env["ROBOCORE_UID"] = str(uid)
    if user is not None:
        env["USER"] = user
    want_uid = os.getuid() if uid is None else uid
    out = ok(shell(project, "ws", "touch mine && sudo -n touch by-sudo && id -un && id -u && pwd && echo $HOME "
                   "&& sudo -n id -u && id -Gn | tr ' ' ,", env=env)).split()
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


def test_image_without_sudo_still_gets_the_user(project: Path) -> None:
    out = ok(shell(project, "bare", "id -un; id -u; pwd; test -e /run/robocore/no-sudo && echo no-sudo",
                   env={"ROBOCORE_UID": "1000", "USER": "alice"})).split()
    assert out == ["alice", "1000", "/home/alice", "no-sudo"]


def test_second_shell_joins_the_first_and_new_starts_another(project: Path, docker_client: Any) -> None:
    name = project.name
    first = background_shell(
        project, "ws", "echo here > /tmp/first-was-here; while [ ! -e /tmp/stop ]; do sleep 0.1; done; echo first-done")
    try:
        container_name = naming.shell_container_name(name, "ws")
        _wait_for_file(docker_client, container_name, "/tmp/first-was-here", first)
        first_id = docker_client.containers.get(container_name).id

        joined = ok(shell(project, "ws", "cat /tmp/first-was-here"))
        assert joined.strip() == "here"  # /tmp is private to the container: same container
        assert docker_client.containers.get(container_name).id == first_id
        assert [c.name for c in _containers(docker_client, name)] == [container_name]

        # negative control: --new is another container, which has no such file
        other = shell(project, "ws", "echo $ROBOCORE_CONTAINER; cat /tmp/first-was-here", "--new")
        assert other.returncode != 0
        assert other.stdout.split()[0] == naming.shell_container_name(name, "ws", 1)
        assert docker_client.containers.get(container_name).id == first_id

        ok(shell(project, "ws", "touch /tmp/stop"))
        stdout, stderr = first.communicate(timeout=60)
        assert first.returncode == 0, stderr
        assert "first-done" in stdout
    finally:
        if first.poll() is None:
            first.kill()
    # the last session left: no dev container is left behind
    assert _containers(docker_client, name) == []


def test_spec_change_is_reported_when_joining(project: Path, docker_client: Any) -> None:
    first = background_shell(project, "ws", "while [ ! -e /tmp/stop ]; do sleep 0.1; done")
    try:
        _wait_for_file(docker_client, naming.shell_container_name(project.name, "ws"), "/run/robocore/ready", first)
        same = shell(project, "ws", "true")
        assert "differs" not in same.stderr  # negative control: same spec, no note
        changed = shell(project, "ws", "touch /tmp/stop", "--devices", "all")
        assert ok(changed) == ""
        assert "differs" in changed.stderr and "--new" in changed.stderr
        first.communicate(timeout=60)
    finally:
        if first.poll() is None:
            first.kill()


def test_interactive_login_shell_has_prompt_aliases_and_persistent_history(project: Path) -> None:
    script = shutil.which("script")
    assert script, "util-linux `script` is needed to give the shell a terminal"
    typed = "alias topic cb\necho \"PS1=$PS1\"\necho marker-$((6*7))\nexit 7\n"
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY",)}
    env.update({"ROBOCORE_UID": "1000", "USER": "alice", "TERM": "dumb"})
    command = f"{sys.executable} -m robocore -p {project} shell --component ws"
    done = subprocess.run([script, "-qec", command, "/dev/null"], input=typed, capture_output=True, text=True,
                          env=env, timeout=120)
    assert done.returncode == 7, done.stdout + done.stderr
    assert "alias topic='ros2 topic'" in done.stdout
    assert "marker-42" in done.stdout
    assert f"[{naming.shell_container_name(project.name, 'ws')}]" in done.stdout  # the rendered prompt
    history = (project / ".robocore" / "home" / "alice" / ".bash_history").read_text()
    assert "echo marker-$((6*7))" in history
    # a later container (the first was removed) has the same home
    assert ok(shell(project, "ws", "tail -n 2 ~/.bash_history", env={"ROBOCORE_UID": "1000", "USER": "alice"}))


def test_cmd_gets_a_terminal_when_robocore_has_one(project: Path) -> None:
    """``shell --cmd tmux`` needs a TTY: given when robocore runs on a terminal, not when its output is captured."""
    script = shutil.which("script")
    assert script, "util-linux `script` is needed to give robocore a terminal"
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY",)}
    env["TERM"] = "xterm"
    command = shlex.join([sys.executable, "-m", "robocore", "-p", str(project), "shell", "--component", "ws",
                          "--cmd", "tty || true; echo term=$TERM"])
    on_terminal = subprocess.run([script, "-qec", command, "/dev/null"], capture_output=True, text=True, env=env,
                                 timeout=120, stdin=subprocess.DEVNULL)
    assert on_terminal.returncode == 0, on_terminal.stdout + on_terminal.stderr
    assert "/dev/pts/" in on_terminal.stdout and "term=xterm" in on_terminal.stdout, on_terminal.stdout
    # negative control: the same command with robocore's output captured gets no terminal
    captured = ok(shell(project, "ws", "tty || true"))
    assert "not a tty" in captured and "/dev/pts/" not in captured


def test_staged_image_sources_ros_and_the_install_tree(demo_project: Path) -> None:
    """The template project after stage+build: ROS, the install tree and a SUPER_CLIENT DDS setup."""
    from robocore.project import Project

    proj = Project.load(demo_project)
    comp = next(c for c in proj.robot.components if c.folder)
    packages = sorted(p.parent.name for p in (demo_project / str(comp.folder)).rglob("package.xml"))
    assert packages
    build_dir = demo_project / ".robocore" / "build" / comp.name
    stamp = time.time()
    out = ok(robocore(demo_project, "shell", "--component", comp.name, "--cmd",
                      "python3 -c 'import rclpy; print(\"rclpy-ok\")'; echo \"super=$ROS_SUPER_CLIENT\"; "
                      "echo \"ament=$AMENT_PREFIX_PATH\"; "
                      "cd /tmp && colcon build >/dev/null && echo built"))
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


def test_devices_from_the_component_and_devices_all(project: Path) -> None:
    device = _host_device()
    probe = f"sudo -n sh -c 'exec 3<{device} && echo opened' 2>&1 || true; test -e {device} || echo absent"
    # negative control: by default the device is not there
    default = ok(shell(project, "ws", probe)).split()
    assert "absent" in default and "opened" not in default
    # --devices all: the whole /dev, and the device cgroup lets it be opened
    assert "opened" in ok(shell(project, "ws", probe, "--devices", "all")).split()
    # a component's devices: list
    with (project / "robot.yaml").open("a") as handle:
        handle.write(f"  - name: hw\n    runs_on: dev\n    image: \"{TEST_IMAGE}\"\n    devices: [\"{device}\"]\n")
    assert "opened" in ok(shell(project, "hw", probe)).split()


def test_wayland_socket_reaches_the_container(project: Path) -> None:
    import socket
    import threading

    runtime = Path(tempfile.mkdtemp(prefix="rc-xdg-"))  # short: AF_UNIX paths are limited to 107 bytes
    path = runtime / "wayland-robocore-test"
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(str(path))
    os.chmod(path, 0o777)  # a compositor's socket belongs to the developer; the test may be root
    server.listen(1)

    def answer() -> None:
        conn, _ = server.accept()
        with conn:
            conn.sendall(b"hello-from-the-compositor")

    thread = threading.Thread(target=answer, daemon=True)
    thread.start()
    env = {"XDG_RUNTIME_DIR": str(runtime), "WAYLAND_DISPLAY": path.name, "ROBOCORE_UID": "1000", "USER": "alice"}
    connect = ("python3 -c \"import os, socket; s = socket.socket(socket.AF_UNIX); "
               "s.connect(os.path.join(os.environ['XDG_RUNTIME_DIR'], os.environ['WAYLAND_DISPLAY'])); "
               "print(s.recv(100).decode())\"; stat -c %a:%u \"$XDG_RUNTIME_DIR\"")
    try:
        out = ok(shell(project, "ws", connect, env=env)).split()
    finally:
        server.close()
        shutil.rmtree(runtime, ignore_errors=True)
    assert out == ["hello-from-the-compositor", "700:1000"]
    # negative control: no WAYLAND_DISPLAY, no socket
    out = ok(shell(project, "ws", "echo \"[$WAYLAND_DISPLAY]\"; test -e /robocore/xdg || echo no-xdg",
                   env={"ROBOCORE_UID": "1000"})).split()
    assert out == ["[]", "no-xdg"]


def test_a_foreign_container_with_the_shell_name_is_left_alone(project: Path, docker_client: Any,
                                                               root_image: str) -> None:
    name = naming.shell_container_name(project.name, "ws")
    foreign = docker_client.containers.run(root_image, ["sleep", "60"], name=name, detach=True,
                                           labels={naming.LABEL_PROJECT: project.name})
    try:
        refused = shell(project, "ws", "true")
        assert refused.returncode != 0
        assert "is not a robocore dev shell" in refused.stderr
        foreign.reload()
        assert foreign.status == "running"
    finally:
        foreign.remove(force=True)
