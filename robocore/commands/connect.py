"""connect: a shell (or a command) inside the live container of a component on its host, as a ROS super
client."""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
from typing import TYPE_CHECKING, Any

from robocore.commands.support.context import Options
from robocore.commands.support.hosts import connect as connect_host
from robocore.commands.support.hosts import running_container
from robocore.config.model import DockerAccess, Host
from robocore.errors import DockerError, UsageError
from robocore.plan import discovery, naming
from robocore.plan.addresses import url_host
from robocore.project import Project

if TYPE_CHECKING:
    import docker


#: Interactive shell: bash when the image has it, else sh (a fixed script, nothing interpolated).
SHELL_ARGV = ["sh", "-c", "if command -v bash >/dev/null 2>&1; then exec bash; else exec sh; fi"]


def exec_argv(entrypoint: list[str] | None, command: list[str]) -> list[str]:
    """``command`` behind the container's own entrypoint (ours sources ROS and the install tree)."""
    return [*(entrypoint or []), *command]


def connect(options: Options, *, component: str, cmd: str | None) -> int:
    """A shell (or ``cmd``) in the live container of ``component`` on its host, as a ROS super client."""
    project = options.load()
    comp = project.component(component)
    host = project.host(comp.runs_on)
    name = naming.container_name(project.name, comp.name)
    env = discovery.for_robot(project.robot).observer_environment(host.name)
    command = SHELL_ARGV if cmd is None else ["sh", "-c", cmd]
    if options.dry_run:
        entry = None if comp.image else [naming.ENTRYPOINT]
        where = f"on {host.name} ({'interactive' if cmd is None else 'no tty'}), in {name}"
        options.report.plain(f"{where}: {shlex.join(exec_argv(entry, command))}")
        options.report.plain("environment: " + " ".join(f"{k}={v}" for k, v in sorted(env.items())))
        return 0
    client, container = _require_running(project, host, name, comp.name)
    entrypoint = container.attrs.get("Config", {}).get("Entrypoint") or None
    argv = exec_argv(entrypoint, command)
    if cmd is not None:
        return _exec_streaming(client, container, host, name, argv, env)
    client.close()
    tty = sys.stdin.isatty()
    full, extra_env = interactive_argv(project, host, docker_exec_argv(name, argv, env, tty=tty), tty=tty)
    if host.access is DockerAccess.ssh:
        from robocore.adapters import ssh

        ssh.require_ssh()
        ssh.ensure_control_dir()
    return subprocess.call(full, env={**os.environ, **extra_env})


def docker_exec_argv(name: str, argv: list[str], env: dict[str, str], *, tty: bool) -> list[str]:
    """``docker exec`` of ``argv`` in container ``name``: each variable attached to its flag
    (``--env=K=V``), ``--`` before the container name and the command."""
    return ["docker", "exec", "-it" if tty else "-i", *(f"--env={key}={value}" for key, value in sorted(env.items())),
            "--", name, *argv]


def interactive_argv(project: Project, host: Host, docker_argv: list[str], *,
                     tty: bool) -> tuple[list[str], dict[str, str]]:
    """The local argv of an interactive ``docker exec -it`` on ``host`` and extra environment for it
    (over ssh: the docker argv quoted argument by argument, after ``--`` and the destination)."""
    access = host.access
    if access is DockerAccess.local:
        return docker_argv, {}
    if access is DockerAccess.ssh:
        from robocore.adapters import ssh

        return ["ssh", "-t" if tty else "-T", *ssh.ssh_options(host), "--", ssh.destination(host),
                shlex.join(docker_argv)], {}
    if access is DockerAccess.tls and host.tls is not None:
        from robocore.adapters.docker_hosts import tls_files

        files = tls_files(host, project.root)
        tls = ["--tlsverify", f"--tlscacert={files.ca_cert}", f"--tlscert={files.client_cert}",
               f"--tlskey={files.client_key}"]
        tcp = f"tcp://{url_host(host.ip, host.docker_port or 2376)}"
        return ["docker", *tls, *docker_argv[1:]], {"DOCKER_HOST": tcp}
    return docker_argv, {"DOCKER_HOST": f"tcp://{url_host(host.ip, host.docker_port or 2375)}"}


def _require_running(project: Project, host: Host, name: str, component: str) -> tuple[docker.DockerClient, Any]:
    client = connect_host(project, host, timeout=60)
    container = running_container(client, name)
    if container is None:
        client.close()
        raise UsageError(f"component {component} is not running on host {host.name} (container {name})",
                         hint="start it with `robocore run`; `robocore status` shows every component")
    return client, container


def _exec_streaming(client: docker.DockerClient, container: Any, host: Host, name: str, argv: list[str],
                    env: dict[str, str]) -> int:
    """Run ``argv`` in the container without a TTY, stream its output, return its exit code."""
    try:
        api = client.api
        exec_id = api.exec_create(container.id, argv, environment=env, stdout=True, stderr=True, tty=False)["Id"]
        for out, err in api.exec_start(exec_id, stream=True, demux=True):
            if out:
                sys.stdout.buffer.write(out)
                sys.stdout.flush()
            if err:
                sys.stderr.buffer.write(err)
                sys.stderr.flush()
        code = api.exec_inspect(exec_id).get("ExitCode")
    except Exception as exc:
        if type(exc).__module__.split(".")[0] in {"docker", "requests", "urllib3"}:
            raise DockerError(f"host {host.name}: exec in {name} failed: {exc}") from None
        raise
    finally:
        client.close()
    return int(code) if code is not None else 1
