"""``fleet VERB``: the fleet task's verbs, each handed to its command module."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from robocore.commands.support.context import Options
from robocore.errors import UsageError

#: The verbs of ``robocore fleet``.
VERBS = ("join", "rollout", "status", "rollback", "page", "logs", "connect")


@dataclass(frozen=True)
class PageFlags:
    """``fleet page``'s flags: ``--out DIR`` or ``--serve [--port N] [--bind ADDR]``."""

    out: str | None = None
    serve: bool = False
    port: int | None = None
    bind: str | None = None

    @property
    def given(self) -> bool:
        """True when any of them was given."""
        return self != PageFlags()


def page_flags(out: str | None, serve: bool, port: str | None, bind: str | None) -> PageFlags:
    """``fleet page``'s flags as given on the command line, checked: a blank ``--out`` or ``--bind`` and a
    ``--port`` that is not a number from 0 to 65535 are refused in one line."""
    for value, flag in ((out, "--out"), (bind, "--bind"), (port, "--port")):
        if value is not None and not value.strip():
            raise UsageError(f"{flag} was given an empty value; name one (or leave {flag} out)")
    number = None
    if port is not None:
        text = port.strip()
        if not (text.isascii() and text.isdigit() and len(text) <= 5 and int(text) <= 65535):
            shown = port if len(port) <= 40 else port[:37] + "..."
            raise UsageError(f"--port takes a port number from 0 to 65535 (got {shown!r})")
        number = int(text)
    return PageFlags(out=out, serve=serve, port=number, bind=bind)


def fleet(options: Options, *, verb: str, version: str | None, robots: Sequence[str],
          page: PageFlags | None = None, force: bool = False, component: str | None = None,
          follow: bool = False) -> Any:
    """Run ``fleet VERB``: join, rollout VERSION [--force], status, rollback [ROBOT...], page (--out DIR | --serve),
    logs ROBOT [--component C] [--follow], connect ROBOT COMPONENT."""
    from robocore.commands import fleet_join, fleet_page, fleet_rollout, fleet_status
    from robocore.commands.fleet_manager import manager_faults

    page = page or PageFlags()
    if verb in ("logs", "connect"):
        return _one_robot(options, verb, robots, component, follow=follow)
    if component is not None or follow:
        raise UsageError(f"--component and --follow are fleet logs', not fleet {verb}'s")
    if verb == "page":
        with manager_faults(verb, version):
            return fleet_page.page(options, out=page.out, serve=page.serve, port=page.port, bind=page.bind)
    if page.given:
        raise UsageError(f"--out, --serve, --port and --bind are fleet page's, not fleet {verb}'s")
    if force and verb != "rollout":
        raise UsageError(f"--force is fleet rollout's, not fleet {verb}'s")

    if verb == "join":
        return fleet_join.join(options)
    with manager_faults(verb, version):  # the manager lost (restarting): one line, and what to do
        if verb == "rollout":
            return fleet_rollout.rollout(options, version=version or "", force=force)
        if verb == "status":
            return fleet_status.status(options)
        if verb == "rollback":
            return fleet_rollout.rollback(options, robots=list(robots))
    raise UsageError(f"fleet needs one of {', '.join(VERBS)}", hint="robocore fleet status")


def _one_robot(options: Options, verb: str, robots: Sequence[str], component: str | None, *, follow: bool) -> Any:
    """``fleet logs ROBOT [--component C] [--follow]`` and ``fleet connect ROBOT COMPONENT``: exactly one robot
    (and for connect, a component)."""
    from robocore.commands import fleet_connect, fleet_logs

    usage = "fleet logs ROBOT [--component C] [--follow]" if verb == "logs" else "fleet connect ROBOT COMPONENT"
    if len(robots) != 1 or (verb == "connect" and component is None):
        raise UsageError(f"{usage}: name {'one robot' if len(robots) != 1 else 'the component'} "
                         f"(got {' '.join(robots) or 'none'})")
    if verb == "logs":
        return fleet_logs.logs(options, robot=robots[0], component=component, follow=follow)
    if follow:
        raise UsageError("--follow is fleet logs', not fleet connect's")
    return fleet_connect.connect(options, robot=robots[0], component=component or "")
