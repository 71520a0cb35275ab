"""The health gate's reason, in words, for a task that ended on its own (pure: the task's fields in, one phrase
out). A task Swarm rejected because its node has no such image is a pull that failed (Swarm's agent pulls first and
only logs a failed pull; the container's create then finds no image), so the reason says so: a registry that is down
or unreachable from the robot, or one that refuses the robot's credentials, reads the same on the robot's side."""

from __future__ import annotations

#: How Docker words a task whose image is not on its node when its container is made.
NO_SUCH_IMAGE = "No such image"


def task_ended(component: str, state: str, exit_code: int | None, error: str, hint: str = "") -> str:
    """Why ``component``'s new task failed the gate: its state, exit code and the daemon's error, then ``hint`` (what
    to check, e.g. the registry's login and CA), or, for an image the node could not pull, that it could not pull
    it."""
    # a rejected task never ran (Swarm reports its container's zero exit code all the same): no code to give
    code = f" with code {exit_code}" if exit_code is not None and state != "rejected" else ""
    reason = f"{component} {state}{code}" + (f": {error}" if error else "")
    if hint:
        reason += f" ({hint})"
    elif state == "rejected" and error.startswith(NO_SUCH_IMAGE):
        reason += " (the robot could not pull the image: is the registry up, and reachable from the robot?)"
    return reason + " (restarting)"
