"""``fleet connect ROBOT COMPONENT``: a shell in the live container of a robot's component, found through the
manager and entered through the robot host's own Docker daemon.

The manager says which task of the component's service runs now, on which node, in which container (and the
command its container was started with, so the shell runs behind the same entrypoint, which sources ROS). Swarm has
no exec or attach for a task, through the manager or otherwise: the shell is ``docker exec`` on the robot host's
daemon, reached as fleet.yaml and robot.yaml say (ssh, TLS or TCP, as ``robocore connect`` reaches it), as a ROS
super client of the robot's graph. So this verb, unlike ``fleet logs``, needs the robot host to be reachable from
here (docs/fleets.md, "Logs and a shell", says why and what was considered).
"""

from __future__ import annotations

import os
import shlex
import subprocess
import sys

from robocore.adapters import swarm, swarm_tasks
from robocore.commands.connect import SHELL_ARGV, docker_exec_argv, exec_argv, interactive_argv
from robocore.commands.fleet_swarm import load, manager_client, manager_line, robot_nodes
from robocore.commands.support.context import Options
from robocore.config.model import DockerAccess
from robocore.errors import HostError, UsageError
from robocore.plan import discovery, naming
from robocore.plan import swarm_services as plan
from robocore.plan.fleet_parts import component_of

#: What a dry run shows in place of the container of the running task, which the manager would name.
UNKNOWN_CONTAINER = "TASK_CONTAINER"


def connect(options: Options, *, robot: str, component: str) -> int:
    """A shell in ``component``'s live container on ``robot`` (see the module); the shell's exit code."""
    fleet = load(options)
    part = component_of(fleet.name, fleet.instances, robot, component)
    instance = fleet.instances[robot]
    host = instance.host(part.host)
    env = discovery.for_robot(instance).observer_environment(host.name)
    tty = sys.stdin.isatty()
    if options.dry_run:
        entry = None if any(c.name == component and c.image for c in instance.components) else [naming.ENTRYPOINT]
        argv = docker_exec_argv(UNKNOWN_CONTAINER, exec_argv(entry, SHELL_ARGV), env, tty=tty)
        full, _ = interactive_argv(fleet.project, host, argv, tty=tty)
        options.report.plain(manager_line(fleet))
        options.report.plain(f"would ask the manager for the running task of service {part.service}, then on "
                             f"{robot}'s host {host.name}: {shlex.join(full)}")
        return 0
    client = manager_client(fleet)
    try:
        nodes = robot_nodes(swarm.nodes(client), fleet).get(robot, [])
        task = swarm_tasks.running_task(client, part.service)
    finally:
        client.close()
    node = next((n for n in nodes if n.labels.get(plan.NODE_HOST) == part.host), None)
    if node is None or node.state != "ready":
        raise HostError(f"{robot}'s host {part.host} is offline (its swarm node is "
                        f"{'not joined' if node is None else node.state}): its containers cannot be entered")
    if task is None or task.node_id != node.id:
        raise UsageError(f"{robot}'s {component} runs no task on its host {part.host} now",
                         hint="robocore fleet status shows what each robot runs")
    argv = exec_argv(list(task.entrypoint) or None, SHELL_ARGV)
    full, extra_env = interactive_argv(fleet.project, host, docker_exec_argv(task.container, argv, env, tty=tty),
                                       tty=tty)
    if host.access is DockerAccess.ssh:
        from robocore.adapters import ssh

        ssh.require_ssh()
        ssh.ensure_control_dir()
    return subprocess.call(full, env={**os.environ, **extra_env})
