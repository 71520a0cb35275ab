"""shell: a dev container in a component's environment.

Plan (:mod:`robocore.plan.devshell`), then execute: write the shell files, the DDS profiles
and the xauth cookie under ``.robocore/``, create and start the container (or join the
running one), and ``docker exec`` a login bash or ``bash -lc CMD`` as the developer. When the
last session of a container ends, the container is removed (its home and workspace live on
the dev machine), as a ``docker run --rm`` shell would be.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import replace
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

from robocore.adapters import x11
from robocore.adapters.docker_hosts import local_client
from robocore.commands.support.context import Options
from robocore.commands.support.host_build import fetch_install
from robocore.commands.support.machine import check_emulation, native_arch
from robocore.commands.support.reporting import Reporter
from robocore.errors import DockerError, ToolMissing, UsageError
from robocore.files import PRIVATE, SHARED, make_folder, remove_tree, write_atomic
from robocore.plan import devshell as plan
from robocore.plan import discovery, naming
from robocore.plan.gui import X11_SOCKETS
from robocore.plan.remote_build import builds_on_host
from robocore.project import Project

if TYPE_CHECKING:
    import docker
    from docker.models.containers import Container

UID_ENV = "ROBOCORE_UID"
GID_ENV = "ROBOCORE_GID"
READY_MARK = "robocore-shell: ready"
READY_TIMEOUT = 60.0
#: What ``--devices all`` is warned with when the shell starts.
DEVICES_ALL_WARNING = ("--devices all: every device of this machine's /dev (disks, input devices, cameras) "
                       "is passed into the shell container")


def run(options: Options, *, component: str, cmd: str | None, new: bool, devices: str | None,
        gpus: bool | None, privileged: bool) -> int:
    """Open (or join) the dev container of ``component``; return the shell's exit code."""
    project = options.load()
    comp = project.component(component)
    if devices not in (None, "all"):
        raise UsageError(f"--devices takes only 'all' (got {devices!r})",
                         hint=f"the devices listed under component {comp.name} in robot.yaml are always passed")
    uid, gid = identity()
    request = plan.ShellRequest(component=comp.name, devices_all=devices == "all", gpus=gpus, privileged=privileged)

    client = None if options.dry_run else local_client()
    if new:
        number = 1 if client is None else _free_number(client, project, comp.name)
        request = replace(request, number=number)
    machine = gather_machine(project, request, uid=uid, gid=gid,
                             nvidia=False if client is None else nvidia_runtime(client))
    existing = frozenset(m.source for m in plan.volume_mounts(project, comp)[0] if Path(m.source).exists())
    spec = plan.plan_shell(project, request, machine,
                           dds_env=discovery.for_robot(project.robot).observer_environment(),
                           existing_paths=existing)
    argv = plan.exec_argv(spec, cmd=cmd, stdin_tty=sys.stdin.isatty(), stdout_tty=sys.stdout.isatty())

    report = options.report
    if options.dry_run or client is None:
        out = plan.describe(spec)
        out["exec"] = argv
        report.plain(json.dumps(out, indent=2))
        return 0

    if request.devices_all:  # said even with --quiet: the shell gets the whole machine's hardware
        report.notice(f"warning: {DEVICES_ALL_WARNING}")
    for note in spec.notes:
        report.info(f"note: {note}")
    docker_cli = shutil.which("docker")
    if docker_cli is None:
        raise ToolMissing("the docker command-line client is not installed (the shell runs `docker exec`)",
                          hint="install it (Debian: apt-get install docker.io, or docker-ce-cli)")
    argv[0] = docker_cli
    host = project.robot.host(comp.runs_on)
    if comp.has_workspace and builds_on_host(host):
        fetch_install(project, comp, host, report)

    with _container_lock(project, spec.name):
        container = None if new else _running(client, spec.name)
        if container is not None:
            _warn_if_stale(client, container, spec, report)
            _refresh_cookie(project, spec, report)
        else:
            container = _create(client, project, spec, machine, report)
        proc = subprocess.Popen(argv)
        _wait_session_registered(client, container, proc)
    try:
        code = _wait(proc)
    finally:
        with _container_lock(project, spec.name):
            _remove_if_idle(client, container, project, spec.name)
    return code


# --- facts about the developer's machine -------------------------------------------------


def identity() -> tuple[int, int]:
    """The developer's UID and GID: ``ROBOCORE_UID``/``ROBOCORE_GID`` when set, else this process's."""
    try:
        uid_text = os.environ.get(UID_ENV)
        uid = int(uid_text) if uid_text else os.getuid()
        gid_text = os.environ.get(GID_ENV)
        gid = int(gid_text) if gid_text else (uid if uid_text else os.getgid())
    except ValueError:
        raise UsageError(f"{UID_ENV}/{GID_ENV} must be numbers") from None
    return uid, gid


def gather_machine(project: Project, request: plan.ShellRequest, *, uid: int, gid: int,
                   nvidia: bool) -> plan.DevMachine:
    """Read the session's display, Wayland socket, terminal and device groups."""
    comp = project.component(request.component)
    display = os.environ.get("DISPLAY") or None
    wayland = os.environ.get("WAYLAND_DISPLAY") or None
    wayland_socket = None
    if wayland:
        path = Path(wayland) if wayland.startswith("/") else Path(os.environ.get("XDG_RUNTIME_DIR", "")) / wayland
        if path.is_absolute() and path.exists():
            wayland_socket = str(path)
    gids: set[int] = set()
    for device in plan.device_paths(comp, devices_all=request.devices_all):
        if request.devices_all:
            continue  # /dev as a whole: the image's hardware groups are joined by name
        try:
            gids.add(os.stat(device).st_gid)
        except OSError:
            raise UsageError(f"component {comp.name}: device {device} does not exist on this machine",
                             hint="plug it in, or remove it from the component's devices in robot.yaml") from None
    gids.discard(0)
    term = os.environ.get("TERM") if sys.stdin.isatty() else None
    return plan.DevMachine(
        uid=uid, gid=gid, user=os.environ.get("USER"), display=display,
        x11_sockets=Path(X11_SOCKETS).is_dir(), xauth_cookie=False, wayland_socket=wayland_socket,
        nvidia_runtime=nvidia, device_gids=tuple(sorted(gids)), term=term,
    )


def nvidia_runtime(client: docker.DockerClient) -> bool:
    """True when the daemon lists an NVIDIA runtime (``docker info``)."""
    try:
        runtimes = client.info().get("Runtimes") or {}
    except Exception:  # an info failure only means "no GPUs"
        return False
    return any("nvidia" in name for name in runtimes)


# --- containers --------------------------------------------------------------------------


def _get(client: docker.DockerClient, name: str) -> Container | None:
    from docker.errors import NotFound

    try:
        return client.containers.get(name)
    except NotFound:
        return None


def _running(client: docker.DockerClient, name: str) -> Container | None:
    container = _get(client, name)
    if container is None:
        return None
    if (container.labels or {}).get(naming.LABEL_ROLE) != plan.ROLE:
        raise DockerError(f"a container named {name} exists and is not a robocore dev shell",
                          hint=f"rename or remove it (docker rm -f {name}) to use robocore shell here")
    if container.status == "running":
        return container
    container.remove(force=True)  # a stopped leftover: start afresh
    return None


def _free_number(client: docker.DockerClient, project: Project, component: str) -> int:
    number = 1
    while _get(client, naming.shell_container_name(project.name, component, number)) is not None:
        number += 1
    return number


def _warn_if_stale(client: docker.DockerClient, container: Container, spec: plan.ShellSpec,
                   report: Reporter) -> None:
    if report.quiet:
        return
    labels = container.labels or {}
    reasons = []
    if labels.get(naming.LABEL_SPEC) != spec.labels[naming.LABEL_SPEC]:
        reasons.append("its configuration (mounts, environment, display, devices or GPUs) differs from now")
    try:
        if client.images.get(spec.image).id != container.attrs.get("Image"):
            reasons.append(f"image {spec.image} was rebuilt since it started")
    except Exception:  # image gone: nothing to compare
        pass
    for reason in reasons:
        report.info(f"note: joining the running dev container {spec.name}, but {reason}; "
                    "leave all its shells to start a fresh one, or use --new")


def _ensure_dir(path: Path, owner: tuple[int, int]) -> None:
    created = not os.path.lexists(path)
    make_folder(path)
    if created and os.geteuid() == 0 and owner != (0, 0):
        os.chown(path, *owner)


def _write_files(project: Project, spec: plan.ShellSpec) -> None:
    folder = project.shell_dir
    source = resources.files("robocore.resources").joinpath("shell")
    for name in plan.SHELL_FILES:
        write_atomic(folder / name, source.joinpath(name).read_bytes(), mode=SHARED)
    for name, text in discovery.for_robot(project.robot).files().items():
        write_atomic(project.dds_dir / name, text, mode=SHARED)
    owner = (spec.uid, spec.gid)
    for mount in spec.mounts:
        src = Path(mount.source)
        if mount.target == spec.home or mount.target in plan.BUILD_TARGETS:
            _ensure_dir(src, owner)
        elif mount.target == plan.CONTAINER_X11:
            make_folder(src, private=True)


def _refresh_cookie(project: Project, spec: plan.ShellSpec, report: Reporter) -> bool:
    display = spec.session_env.get("DISPLAY")
    if not display:
        return False
    folder = project.x11_dir(spec.name)
    try:
        written = x11.write_cookie_file(display, folder, file_name=plan.XAUTH_FILE, owner=(spec.uid, spec.gid))
    except ToolMissing as missing:
        report.notice(f"note: {missing.message}")
        return False
    if not written:
        report.notice(f"note: no xauth cookie for DISPLAY={display}: X programs may be refused")
    return written


def _create(client: docker.DockerClient, project: Project, spec: plan.ShellSpec, machine: plan.DevMachine,
            report: Reporter) -> Container:
    from docker.errors import APIError, ImageNotFound

    comp = project.component(spec.component)
    try:
        client.images.get(spec.image)
    except ImageNotFound:
        hint = (f"pull or build it (component {comp.name} uses image: {spec.image})" if comp.image
                else f"run `robocore stage --component {comp.name}` first")
        raise UsageError(f"component {comp.name}: image {spec.image} is not on this machine", hint=hint) from None
    # an image of another arch (an arm64 host's component) runs emulated, or is refused in one line
    check_emulation(project.robot.host(comp.runs_on).arch.value, native_arch(), f"the shell of component {comp.name}")
    _write_files(project, spec)
    _refresh_cookie(project, spec, report)
    kwargs: dict[str, Any] = spec.container_kwargs()
    if spec.gpus:
        from docker.types import DeviceRequest

        kwargs["device_requests"] = [DeviceRequest(count=-1, capabilities=[["gpu"]])]
    try:
        container = client.containers.create(**kwargs)
    except APIError as exc:
        if exc.status_code == 409:  # another `shell` created it a moment ago: join that one
            existing = _running(client, spec.name)
            if existing is not None:
                return existing
        raise DockerError(f"component {comp.name}: cannot create dev container {spec.name}: {_explain(exc)}",
                          hint=_hint(spec, exc)) from None
    try:
        container.start()
    except APIError as exc:
        container.remove(force=True)
        raise DockerError(f"component {comp.name}: cannot start dev container {spec.name}: {_explain(exc)}",
                          hint=_hint(spec, exc)) from None
    report.info(f"started dev container {spec.name} from {spec.image}")
    _wait_ready(container, spec)
    return container


def _explain(exc: Exception) -> str:
    text = getattr(exc, "explanation", None) or str(exc)
    return str(text).splitlines()[0] if text else type(exc).__name__


def _hint(spec: plan.ShellSpec, exc: Exception) -> str | None:
    text = str(exc)
    if spec.privileged and "caps" in text:
        return "this Docker daemon cannot run privileged containers; drop --privileged"
    if spec.gpus and ("device driver" in text or "gpu" in text.lower()):
        return "no usable NVIDIA runtime: use --no-gpus, or install the NVIDIA container toolkit"
    if "no such file" in text.lower() or "does not exist" in text.lower():
        return "a mounted path or device is missing on this machine"
    return None


def _wait_ready(container: Container, spec: plan.ShellSpec) -> None:
    deadline = time.monotonic() + READY_TIMEOUT
    while True:
        logs = container.logs().decode(errors="replace")
        if READY_MARK in logs:
            return
        container.reload()
        if container.status not in ("created", "running") or time.monotonic() > deadline:
            tail = " | ".join(logs.strip().splitlines()[-5:]) or "no output"
            container.remove(force=True)
            raise DockerError(f"component {spec.component}: dev container {spec.name} did not get ready: {tail}",
                              hint="does the image have /bin/sh and bash?")
        time.sleep(0.1)


@contextlib.contextmanager
def _container_lock(project: Project, name: str) -> Iterator[None]:
    """Serialise "find or create, then start a session" against "last session left, remove"."""
    folder = project.shell_dir
    make_folder(folder, shared=True)
    fd = os.open(folder / f".{name}.lock", os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK, PRIVATE)
    with os.fdopen(fd, "a+b") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def _running_sessions(client: docker.DockerClient, container: Container) -> int:
    from docker.errors import NotFound

    container.reload()
    running = 0
    for exec_id in container.attrs.get("ExecIDs") or []:
        try:
            running += bool(client.api.exec_inspect(exec_id).get("Running"))
        except NotFound:
            continue
    return running


def _wait_session_registered(client: docker.DockerClient, container: Container, proc: subprocess.Popen[bytes],
                             timeout: float = 10.0) -> None:
    """Wait until Docker lists a running exec in the container (or the session already ended)."""
    deadline = time.monotonic() + timeout
    while proc.poll() is None and time.monotonic() < deadline:
        if _running_sessions(client, container):
            return
        time.sleep(0.05)


def _wait(proc: subprocess.Popen[bytes]) -> int:
    while True:
        try:
            return proc.wait()
        except KeyboardInterrupt:
            continue  # the session received the interrupt too; wait for it to finish


def _remove_if_idle(client: docker.DockerClient, container: Container, project: Project, name: str) -> None:
    """Remove the container when no session runs in it any more (its state lives on the dev machine)."""
    from docker.errors import APIError, NotFound

    try:
        if _running_sessions(client, container):
            return
        container.remove(force=True)
    except NotFound:
        pass
    except APIError as exc:
        raise DockerError(f"cannot remove dev container {name}: {_explain(exc)}") from None
    remove_tree(project.x11_dir(name), ignore_errors=True)
