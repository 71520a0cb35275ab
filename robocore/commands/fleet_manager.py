"""The swarm's manager as a fault: lost in the middle of a command, or just restarted.

A ``fleet`` command that loses the manager (its daemon restarting, its host rebooting) ends with one line saying
so and what to do, never a traceback. A rollout that was cut off leaves the fleet in a state ``fleet rollout V``
run again finishes: the robots it had changed already hold V in their services' labels and are gated again without
being restarted (:func:`~robocore.adapters.swarm.apply_service` changes labels only when the template is the same),
the others are changed as before. Two things of a restart are handled before the rerun's first wave
(:func:`settle`):

- a manager that has just started has no leader for a moment and marks every node ``unknown`` until that node's
  agent reconnects (swarmkit does so on every change of leader); a rollout then would take the robots for offline and
  report them pending, so it waits a bounded time (:data:`SETTLE`) for the manager to hear from them again;
- the health and lock probes of the run that was cut off are one-shot services nobody removes: those that ended are
  removed, before the first wave and after the last (:func:`clear_probes`).
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

from robocore.adapters import swarm
from robocore.commands.fleet_swarm import FleetProject, project_label, robot_nodes, unheard
from robocore.errors import DockerError, HostError, RobocoreError
from robocore.plan import swarm_services as plan

if TYPE_CHECKING:
    import docker

    from robocore.commands.support.reporting import Reporter

#: Seconds a rollout waits, before its first wave, for a manager that has just started to have a leader and to hear
#: again from the fleet's nodes (their agents reconnect within seconds); past it, the nodes it has not heard from are
#: taken for offline, as the manager itself then takes them.
SETTLE = 30.0
#: Seconds between two looks while settling.
POLL = 0.5
#: What Swarm answers while a manager's daemon starts (no leader yet) or stops (its control socket gone).
NO_LEADER = ("does not have a leader", "not a swarm manager", "rpc error: code = Unavailable")


def lost(exc: BaseException) -> bool:
    """Whether ``exc`` is the manager's connection lost, refused or cut (its daemon or host restarting), as
    docker-py, requests and urllib3 raise it, or the 503 of a manager with no leader yet."""
    import urllib3
    from docker.errors import APIError

    if isinstance(exc, APIError):
        return exc.status_code == 503 or any(text in str(exc) for text in NO_LEADER)
    # requests' errors are OSErrors; a stream cut in the middle of a response is urllib3's
    return isinstance(exc, (OSError, urllib3.exceptions.HTTPError))


def again_hint(verb: str, version: str | None) -> str:
    """What to do once the manager answers again after ``fleet VERB`` lost it."""
    if verb == "rollout":
        return (f"once the manager answers again, run `robocore fleet rollout {version}` again: it finishes what this "
                f"one started (robots already on {version} are gated again, not restarted)")
    if verb == "rollback":
        return ("once the manager answers again, roll out the release the robots were going back to (`robocore fleet "
                "rollout VERSION`, which finishes it); `fleet rollback` again would take the robots it had already "
                "moved back to the release they left")
    if verb in ("status", "page"):
        return f"fleet {verb} reads the fleet's state from the manager only: until it answers, that state is not known"
    return f"run `robocore fleet {verb}` again once the manager answers"


@contextmanager
def manager_faults(verb: str, version: str | None) -> Iterator[None]:
    """Turn the manager lost in the middle of ``fleet VERB`` into one line with what to do; a manager that cannot
    be reached at all (a HostError naming it), or that is starting or stopping, gets the same advice."""
    try:
        yield
    except HostError as error:
        if "host manager:" not in error.message:
            raise
        raise HostError(error.message, hint=again_hint(verb, version)) from None
    except DockerError as error:
        if not any(text in error.message for text in NO_LEADER):
            raise
        raise DockerError(f"the swarm's manager is not serving as one (its daemon starting or stopping) during "
                          f"fleet {verb}: {error.message}", hint=again_hint(verb, version)) from None
    except RobocoreError:
        raise
    except Exception as exc:
        if not lost(exc):
            raise
        text = str(exc).strip().splitlines()
        raise HostError(f"lost the swarm's manager during fleet {verb}: {text[0] if text else type(exc).__name__}",
                        hint=again_hint(verb, version)) from None


def settle(client: docker.DockerClient, fleet: FleetProject, report: Reporter, wait: float = SETTLE) -> None:
    """Before a rollout's or a rollback's first change: wait (at most ``wait`` seconds) until the manager has a
    leader and has heard from every node of the fleet since it started; then remove the ended probes a run that
    was cut off left (see the module)."""
    deadline = time.monotonic() + wait
    told = False
    while True:
        try:
            by_robot = robot_nodes(swarm.nodes(client), fleet)
            waiting = sorted(robot for robot in fleet.instances if unheard(robot, by_robot, fleet))
        except DockerError as error:
            if not any(text in error.message for text in NO_LEADER) or time.monotonic() > deadline:
                raise
            waiting = ["(the manager has no leader yet)"]
        if not waiting or time.monotonic() > deadline:
            break
        if not told:
            report.info(f"waiting up to {wait:g} s for the manager, which has just started, to hear again from: "
                        f"{', '.join(waiting)}")
            told = True
        time.sleep(POLL)
    clear_probes(client, fleet)


def clear_probes(client: docker.DockerClient, fleet: FleetProject) -> None:
    """Remove the project's probes whose task has ended: those a run that was cut off left (a run removes its own
    as it reads them). Called before a rollout's first wave and after its last, by when one of them that was
    still running then has ended (a probe ends on its own: its verdict, or its timeout)."""
    for service in swarm.services(client, project_label(fleet)):
        if plan.LABEL_PROBE in service.labels:
            found = swarm.tasks(client, service.name)
            if all(task.state in swarm.ENDED for task in found):
                swarm.remove_service(client, service.name)
