"""``status`` of an unchanged project on this machine, without loading robot.yaml's model, invoke or docker-py.

What ``status`` lists comes from two places: robot.yaml says which containers each host should run (the plan),
and the hosts' Docker daemons say which run. When every host of the robot is this machine, an ordinary
``status`` records its plan (each host's planned names, the discovery servers, whether the discovery kind's
nodes register only when they start) in ``.robocore/noop/``, under the same snapshot of the project and
robocore's code that the no-op memo of ``validate`` uses (:mod:`robocore.commands.support.noop`). The next plain
``robocore status`` whose fresh snapshot equals it takes the plan from there, asks the daemon over its unix
socket (:mod:`robocore.adapters.docker_socket`) and prints the same table
(:mod:`robocore.commands.support.status_table`).

Anything else takes the ordinary path: a flag (``--json``, ``--nodes``, ``--dry-run``), a changed file, a host
that is not this machine, a daemon that does not answer on its socket. The plan is only ever read from a memo
whose snapshot matches, and a snapshot holds each file's inode and change time: a memo that came with a clone
of the project never matches.
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence

from robocore.commands.support import noop

#: The task, and the flags its fast path takes (none: ``--json``, ``--nodes`` and ``--dry-run`` go the ordinary way).
TASK = "status"
FLAGS: dict[str, bool] = {}


def memo_for(argv: Sequence[str]) -> noop.Memo | None:
    """The memo of a plain ``status`` command line (``status``, ``-p DIR status``, ``DIR status``), else None."""
    return noop.for_command(argv, tasks=(TASK,), flags=FLAGS)


def plan_document(project: str, hosts: Sequence[tuple[str, Sequence[str]]], servers: Sequence[str], *,
                  register_once: bool) -> dict[str, object]:
    """What the memo keeps: the project's name (its containers' label), each host with its planned names in
    order, the discovery servers' names and whether the kind's nodes register only when they start."""
    return {"project": project, "hosts": [[name, list(planned)] for name, planned in hosts],
            "servers": list(servers), "register_once": register_once}


def _plan(recorded: dict[str, object]) -> tuple[str, list[tuple[str, list[str]]], list[str], bool] | None:
    project, hosts, servers, once = (recorded.get(k) for k in ("project", "hosts", "servers", "register_once"))
    if not isinstance(project, str) or not isinstance(hosts, list) or not isinstance(servers, list):
        return None
    plan = []
    for entry in hosts:
        if not (isinstance(entry, list) and len(entry) == 2 and isinstance(entry[0], str)
                and isinstance(entry[1], list) and all(isinstance(n, str) for n in entry[1])):
            return None
        plan.append((entry[0], list(entry[1])))
    if not all(isinstance(n, str) for n in servers):
        return None
    return project, plan, [str(n) for n in servers], bool(once)


def answer(argv: Sequence[str]) -> bool:
    """Print the status of an unchanged all-local project from its memo and the daemon; True when done, False
    when the ordinary path must run (nothing printed then)."""
    memo = memo_for(argv)
    if memo is None or not memo.exists():
        return False
    recorded = memo.current()
    plan = _plan(recorded) if recorded is not None else None
    if plan is None:
        return False
    project, hosts, servers, register_once = plan
    from robocore.adapters import docker_socket
    from robocore.commands.support.status_table import (
        NOT_ASKED,
        host_rows,
        managed,
        not_registered,
        print_status,
        stale_line,
    )
    from robocore.plan.naming import LABEL_PROJECT

    found = docker_socket.containers(f"{LABEL_PROJECT}={project}")
    if found is None:
        return False
    documents = managed(found)
    rows = [row for host, planned in hosts for row in host_rows(host, planned, documents)]
    from robocore.commands.support.reporting import Reporter

    report = Reporter(TASK)
    print_status(rows, {}, None, NOT_ASKED, report=report)
    stale = not_registered(rows, servers) if register_once else []
    if stale:
        report.out(stale_line(stale))
    return True


def record(memo: noop.Memo, document: dict[str, object]) -> None:
    """After an ordinary ``status`` that listed every host: keep its plan when the project did not change
    meanwhile (nothing is kept otherwise, nor when the memo cannot be written: the next run is ordinary)."""
    with contextlib.suppress(OSError):
        memo.keep(document)
