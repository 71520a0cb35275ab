"""``fleet page``: the fleet as a page in a browser, written once (``--out DIR``) or served live (``--serve``).

A look reads what ``fleet status`` reads from the manager (:func:`robocore.commands.fleet_status.observe`: nodes,
services with their release labels, tasks), adds each robot's labels and wave from fleet.yaml and the fleet
release records of ``.robocore/releases/``, and hands the pure :mod:`robocore.plan.fleet_page` a
:class:`~robocore.plan.fleet_page.FleetView` to render. Nothing is changed anywhere: the page only reads.

- ``--dry-run`` says how the manager would be reached and what would be written or served, and contacts nothing.
- ``--out DIR`` writes ``DIR/index.html``: one file, its CSS inline, that opens from ``file://`` with no network
  (a CI artefact, an incident report). DIR must not be a link; a file robocore did not write there is replaced
  only when it is a regular file (``files.write_atomic``: never through a link).
- ``--serve`` serves the page on ``--bind`` (127.0.0.1 unless told: the page names robots and releases, so
  another address is a choice, warned about) at ``--port`` (8765; 0 picks a free one) until Ctrl-C. The page
  polls the changing part every :data:`~robocore.plan.fleet_page.LIVE_INTERVAL` seconds; the server looks at the
  manager at most once per interval, however many pages are open (docs/fleets.md, "The fleet page", says why
  polling rather than server-sent events).
"""

from __future__ import annotations

import contextlib
import ipaddress
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import ClassVar

from robocore.commands.fleet_status import FleetRobotRow, Observed, observe, status_rows
from robocore.commands.fleet_swarm import FleetProject, load, manager_line, now
from robocore.commands.support.context import Options
from robocore.errors import RobocoreError, UnsafePath, UsageError
from robocore.export_folder import path_text
from robocore.plan import naming
from robocore.plan import swarm_services as plan
from robocore.plan.fleet import plan_waves
from robocore.plan.fleet_page import (
    LIVE_INTERVAL,
    ComponentView,
    FleetView,
    ReleaseView,
    RobotView,
    render_fleet,
    render_page,
)
from robocore.project import Project

#: The file ``--out DIR`` writes.
SNAPSHOT = "index.html"
#: ``--port`` when none is given.
DEFAULT_PORT = 8765
#: ``--bind`` when none is given: this machine only.
DEFAULT_BIND = "127.0.0.1"


@dataclass(frozen=True)
class FleetPage:
    """What ``fleet page`` made: the snapshot's path and size, or the address it served."""

    kind: ClassVar[str] = "fleet_page"
    robots: int
    path: str = ""
    bytes: int = 0
    url: str = ""


def _components(robot: str, observed: Observed) -> tuple[ComponentView, ...]:
    """``robot``'s component services, each with the state of its newest task that is meant to run (else of its
    newest task: a crash shows as ``failed``)."""
    out = []
    for service in observed.services:
        labels = service.labels
        if labels.get(plan.LABEL_ROBOT) != robot or labels.get(naming.LABEL_ROLE) != naming.ROLE_COMPONENT:
            continue
        tasks = sorted(observed.tasks.get(service.name, []), key=lambda t: t.created, reverse=True)
        meant = [t for t in tasks if t.desired == "running"] or tasks
        out.append(ComponentView(labels.get(naming.LABEL_COMPONENT, service.name),
                                 meant[0].state if meant else "no task"))
    return tuple(sorted(out, key=lambda c: c.name))


def fleet_view(fleet: FleetProject, rows: list[FleetRobotRow], observed: Observed,
               releases: tuple[ReleaseView, ...], taken: str, older_releases: int = 0) -> FleetView:
    """The view of one look: ``fleet status``'s ``rows`` with each robot's labels and wave from fleet.yaml and
    its components from ``observed``, and the release records. Only names, labels, releases, states, reasons and
    the ROS names the last gate saw are taken: a service's environment, a host's address or a registry's
    credentials have no field here."""
    waves = plan_waves(fleet.fleet)
    wave_of = {robot: wave.name for wave in waves for robot in wave.robots}
    labels = {robot.name: tuple(sorted(robot.labels.items())) for robot in fleet.fleet.robots}
    robots = tuple(RobotView(robot=row.robot, wave=wave_of.get(row.robot, "-"), labels=labels.get(row.robot, ()),
                             running=row.running, target=row.target, health=row.health, state=row.state,
                             changed=row.changed, reason=row.reason, components=_components(row.robot, observed),
                             seen=row.seen)
                   for row in rows)
    return FleetView(project=fleet.name, taken=taken, robots=robots, waves=tuple(w.name for w in waves),
                     releases=releases, older_releases=older_releases)


#: The release records a look reads at most: the newest, and those a robot runs or is moving to (a look is taken
#: every few seconds while the page is open, and ``.robocore/releases/`` keeps every release ever recorded).
MAX_RELEASES = 50


def release_views(project: Project, registry: str | None,
                  named: frozenset[str] = frozenset()) -> tuple[tuple[ReleaseView, ...], int]:
    """The fleet release records of ``project``, newest first, believed as rollout believes them (images in the
    fleet's ``registry``); a record that cannot be believed is listed with why (the page still shows the fleet).
    At most :data:`MAX_RELEASES` newest are read, and every one of the versions ``named`` (what the robots run or
    target); returns them and how many older records were left unread."""
    from robocore.commands.fleet_release import load_release_record

    folder = project.releases_dir
    if not folder.is_dir() or folder.is_symlink():
        return (), 0
    records = []  # (mtime, version)
    for path in folder.glob("*.json"):
        with contextlib.suppress(OSError):
            records.append((os.lstat(path).st_mtime, path.name[: -len(".json")]))
    records.sort(key=lambda item: (-item[0], item[1]))
    chosen = [item for n, item in enumerate(records) if n < MAX_RELEASES or item[1] in named]
    found = []
    for mtime, version in chosen:
        recorded = datetime.fromtimestamp(mtime, timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
        try:
            record = load_release_record(project, version, registry)
        except RobocoreError as error:
            found.append(ReleaseView(version, recorded, problem=error.message))
            continue
        images = [(c, a, ref) for c, arches in sorted(record.components.items()) for a, ref in sorted(arches.items())]
        images += [("base", a, ref) for a, ref in sorted(record.base.items())]
        found.append(ReleaseView(record.version, recorded, tuple(images)))
    return tuple(found), len(records) - len(chosen)


def look(fleet: FleetProject) -> FleetView:
    """One look at ``fleet``: the manager read once, the release records read again."""
    observed = observe(fleet)
    taken = now()
    rows = status_rows(fleet, observed)
    named = frozenset(version for row in rows for version in (row.running, row.target))
    releases, older = release_views(fleet.project, fleet.fleet.registry_for(fleet.project.robot), named)
    return fleet_view(fleet, rows, observed, releases, taken, older)


class Looks:
    """The latest look, taken again at most every ``every`` seconds however many pages ask (one lock); when the
    manager cannot be read, the last look is kept and says so."""

    def __init__(self, read: Callable[[], FleetView], every: float = LIVE_INTERVAL,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.read, self.every, self.clock = read, every, clock
        self.lock = threading.Lock()
        self.view = read()
        self.at = clock()

    def current(self) -> FleetView:
        """The look at most ``every`` seconds old (or the last one, with the reason a new one failed)."""
        with self.lock:
            if self.clock() - self.at >= self.every:
                self.at = self.clock()
                try:
                    self.view = self.read()
                except RobocoreError as error:
                    self.view = replace(self.view, problem=f"the manager could not be read at {now()}: "
                                                           f"{error.message}")
            return self.view


def write_snapshot(view: FleetView, out: Path) -> Path:
    """Write ``view``'s page to ``out/index.html`` (``out`` made when missing); UsageError in one line when
    ``out`` is a link, not a folder, or cannot be written."""
    from robocore.files import make_folder, write_atomic

    check_out(out)
    target = out / SNAPSHOT
    try:
        make_folder(out)  # never writable by others, whatever the umask
        write_atomic(target, render_page(view), durable=False)
    except UnsafePath as error:
        raise UsageError(error.message, hint=error.hint) from None
    except OSError as error:
        raise UsageError(f"--out {path_text(out)}: cannot be written ({error.strerror or error})") from None
    return target


def check_out(out: Path) -> None:
    """UsageError in one line when ``out`` cannot be the snapshot's folder (a link, not a folder): what a dry run
    checks too, so that it refuses what the real run refuses."""
    if out.is_symlink():
        raise UsageError(f"--out {path_text(out)}: is a symlink; fleet page writes into a real folder only",
                         hint="name the folder the link points to")
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {path_text(out)}: is not a folder")


def is_loopback(bind: str) -> bool:
    """True for an address only this machine reaches (127.0.0.0/8, ::1, ``localhost``)."""
    if bind == "localhost":
        return True
    try:
        return ipaddress.ip_address(bind).is_loopback
    except ValueError:
        return False


def page(options: Options, *, out: str | None, serve: bool, port: int | None, bind: str | None) -> FleetPage:
    """Write the fleet page to ``out`` or serve it (see the module)."""
    if (out is None) == (not serve):
        raise UsageError("fleet page needs one of --out DIR (a snapshot) or --serve (a live page)",
                         hint="robocore fleet page --serve")
    if out is not None and (port is not None or bind is not None):
        raise UsageError("--port and --bind go with --serve, not --out")
    fleet = load(options)
    report = options.report
    if options.dry_run:  # the page is the manager's state: a dry run contacts nothing
        if out is not None:
            check_out(Path(out))
        where = (f"write {path_text(Path(out) / SNAPSHOT)}" if out is not None else
                 f"serve it at http://{bind or DEFAULT_BIND}:{DEFAULT_PORT if port is None else port}")
        report.plain(manager_line(fleet))
        report.plain(f"would read the state of {len(fleet.instances)} robot(s) from the manager and {where}")
        return FleetPage(robots=len(fleet.instances))
    if out is not None:
        view = look(fleet)
        path = write_snapshot(view, Path(out))
        result = FleetPage(robots=len(view.robots), path=str(path), bytes=path.stat().st_size)
        report.notice(f"wrote {path} ({result.bytes:,} bytes, {result.robots} robot(s)): open it in a browser")
        report.add(result)
        return result
    from robocore.adapters import page_server

    looks = Looks(lambda: look(fleet))
    address = bind or DEFAULT_BIND
    server = page_server.start(page_server.Pages(page=lambda: render_page(looks.current(), live=True),
                                                 part=lambda: render_fleet(looks.current())),
                               address, DEFAULT_PORT if port is None else port)
    if not is_loopback(address):
        report.warn(f"--bind {address}: anyone who reaches this address sees the fleet's robot names, labels, "
                    "releases and gate reasons (read-only; no credentials are on the page)")
    result = FleetPage(robots=len(looks.view.robots), url=server.url)
    report.notice(f"serving the fleet page of {fleet.name} at {server.url} (read-only; Ctrl-C stops it)")
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        report.info("stopped")
    finally:
        server.server_close()
    report.add(result)
    return result
