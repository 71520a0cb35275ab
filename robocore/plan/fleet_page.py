"""The fleet page (pure): one look at a fleet, as the data a page shows and as that page's HTML.

``fleet page`` (:mod:`robocore.commands.fleet_page`) reads the manager once per look and hands this module a
:class:`FleetView`; :func:`render_page` turns it into one HTML document with its CSS inline (no network at view
time, so it opens from ``file://`` on a lab laptop) and :func:`render_fleet` into the part the live page fetches
again while a rollout runs. The template (``resources/fleet-page.html``) is rendered by Jinja2 with autoescape on:
every robot name, label, release, reason and ROS name is text, never markup. What a view holds is what the page may
show: names, labels, releases by digest, states, the gates' reasons and the ROS nodes and topics the last gate saw;
never an environment value, a registry credential or a host's address (the view has no field for them). A reason
or a ROS name is scrubbed of ``password=...``-like words all the same, as it is text a container or a probe wrote.

Every state is said in words and by a symbol as well as a colour (:func:`verdict`), so the page reads in grey and
in print.
"""

from __future__ import annotations

import functools
import re
from collections import Counter
from dataclasses import dataclass
from typing import TYPE_CHECKING

from robocore.plan.gate_graph import Seen

if TYPE_CHECKING:
    import jinja2

#: Seconds between two looks of the live page (``--serve``): the manager is read at most once per interval, what
#: ``fleet rollout`` itself does twice a second while it gates.
LIVE_INTERVAL = 2.0
#: A wave of more robots than this shows those that need a look and folds its healthy ones (a button, or the
#: filter, shows them): laying out table rows is what a big page costs in the browser, not its bytes (1000 robots:
#: the same 570 KB loaded in 0.17 s with one wave's rows folded, 1.9 s with every row laid out, in one run;
#: bench/fleet_page.py).
FOLD_ABOVE = 50
#: What a scrubbed secret-like value becomes.
HIDDEN = "(hidden)"
_SECRET = re.compile(r"(?i)\b([\w.-]*(?:password|passwd|secret|token|api[_-]?key|credential)[\w.-]*)([=:]\s*)\S+")


@dataclass(frozen=True)
class ComponentView:
    """One component service of a robot and the state of its current task (``running``, ``failed``, ...)."""

    name: str
    state: str


@dataclass(frozen=True)
class RobotView:
    """One robot as ``fleet status`` reads it (with the graph its last gate saw), with its labels and wave from
    fleet.yaml and its components."""

    robot: str
    wave: str
    labels: tuple[tuple[str, str], ...] = ()
    running: str = "-"
    target: str = "-"
    health: str = "-"
    state: str = "online"  # online | offline, then pending and busy since T (fleet status's words)
    changed: str = "-"
    reason: str = ""
    components: tuple[ComponentView, ...] = ()
    seen: Seen | None = None  # the ROS graph the last gate's probe saw (None when it ran none)


@dataclass(frozen=True)
class ReleaseView:
    """A fleet release record: its version, when it was recorded, and its images by digest."""

    version: str
    recorded: str  # UTC, ISO 8601 to the second ("-" when unknown)
    images: tuple[tuple[str, str, str], ...] = ()  # (component, or "base"; arch; <registry>/<repo>@sha256:...)
    problem: str = ""  # why the record could not be read ("" when it was)


@dataclass(frozen=True)
class FleetView:
    """One look at a fleet: every robot in fleet-file order, the waves of a rollout, the recorded releases."""

    project: str
    taken: str  # when the manager was read (UTC, ISO 8601)
    robots: tuple[RobotView, ...]
    waves: tuple[str, ...] = ()  # the waves' names in rollout order
    releases: tuple[ReleaseView, ...] = ()
    older_releases: int = 0  # older release records the look did not read
    problem: str = ""  # why this look is an old one (the live page when the manager cannot be read)


@dataclass(frozen=True)
class Verdict:
    """How the page shows a robot's state: a tone (its colour class), a symbol and words."""

    tone: str  # ok | bad | warn | wait | off
    symbol: str
    words: str


def verdict(robot: RobotView) -> Verdict:
    """The state a robot is shown in: a failed gate first (a canary that failed and went back stays red, saying
    which release it is back on), then offline, busy (held back: its update lock, its maintenance window), being
    gated (a target but no verdict yet), pending, healthy."""
    if robot.target == "-" and robot.running in ("-", "?"):
        return Verdict("off", "○", "not deployed")
    if robot.health == "failed":
        return Verdict("bad", "✗", "failed")
    if robot.health == "rolled-back":
        return Verdict("bad", "✗", f"failed, back on {robot.target}")
    if robot.state.startswith(("offline", "unknown")):  # unknown: the manager, just started, has not heard from it
        return Verdict("off", "○", robot.state)
    if "busy since" in robot.state or robot.health == "busy":  # held back by its update lock or window
        return Verdict("warn", "◐", robot.state.split(", ")[-1] if "busy since" in robot.state else "busy")
    if robot.health == "":
        return Verdict("wait", "◔", "being gated")
    if "pending" in robot.state or robot.health == "pending":
        return Verdict("warn", "◐", "pending")
    if robot.health == "healthy":
        return Verdict("ok", "✓", "healthy")
    return Verdict("warn", "?", robot.health or "unknown")


def scrub(text: str) -> str:
    """``text`` with the value of every ``password=...``, ``token: ...``-like word hidden."""
    return _SECRET.sub(lambda m: f"{m.group(1)}{m.group(2)}{HIDDEN}", text)


@dataclass(frozen=True)
class Rollout:
    """What the page says of the rollout: the release most robots target, and who is gated, failed, pending."""

    target: str
    gating: tuple[RobotView, ...]
    failed: tuple[RobotView, ...]
    pending: tuple[RobotView, ...]
    on_target: int
    total: int

    @property
    def words(self) -> str:
        """The rollout in one line."""
        if self.target == "-":
            return "no release rolled out yet"
        if self.gating:
            return f"rollout of {self.target} in progress: {len(self.gating)} robot(s) being gated"
        if self.failed:
            return f"rollout stopped: {len(self.failed)} robot(s) failed the health gate"
        return f"{self.on_target} of {self.total} robot(s) run {self.target}" + \
            (f"; {len(self.pending)} pending" if self.pending else "")


def rollout(view: FleetView) -> Rollout:
    """The rollout as far as one look shows it (the release most robots target is the one being rolled out)."""
    targets = Counter(r.target for r in view.robots if r.target not in ("-", "mixed"))
    target = targets.most_common(1)[0][0] if targets else "-"
    kinds = {r.robot: verdict(r) for r in view.robots}
    return Rollout(target=target,
                   gating=tuple(r for r in view.robots if kinds[r.robot].words == "being gated"),
                   failed=tuple(r for r in view.robots if kinds[r.robot].tone == "bad"),
                   pending=tuple(r for r in view.robots
                                 if "pending" in r.state and kinds[r.robot].tone not in ("wait", "bad")),
                   on_target=sum(r.running == target for r in view.robots), total=len(view.robots))


def runs(view: FleetView, version: str) -> tuple[str, ...]:
    """The robots that run release ``version``."""
    return tuple(r.robot for r in view.robots if r.running == version)


def groups(view: FleetView) -> list[tuple[str, list[RobotView]]]:
    """The robots by wave, the waves in rollout order (a wave the view does not name last), each in file order."""
    by_wave: dict[str, list[RobotView]] = {name: [] for name in view.waves}
    for robot in view.robots:
        by_wave.setdefault(robot.wave, []).append(robot)
    return [(name, robots) for name, robots in by_wave.items() if robots]


def fold(robots: list[RobotView]) -> tuple[list[RobotView], list[RobotView]]:
    """A wave's robots as (shown, folded): a wave of more than :data:`FOLD_ABOVE` robots folds its healthy ones."""
    if len(robots) <= FOLD_ABOVE:
        return robots, []
    healthy = [r for r in robots if verdict(r).tone == "ok"]
    return [r for r in robots if verdict(r).tone != "ok"], healthy


def waves(view: FleetView) -> list[tuple[str, int, list[tuple[str, str, int]]]]:
    """Each wave: its name, its number of robots and how many are in each state (words, tone, count)."""
    out = []
    for name, robots in groups(view):
        tally = Counter((verdict(r).words, verdict(r).tone) for r in robots)
        out.append((name, len(robots), [(words, tone, count) for (words, tone), count in tally.items()]))
    return out


def search_text(robot: RobotView) -> str:
    """What the page's filter matches a robot on: its name, wave and ``key=value`` labels, lower case."""
    return " ".join([robot.robot, f"wave {robot.wave}", *(f"{k}={v}" for k, v in robot.labels)]).lower()


def task_tone(state: str) -> str:
    """The tone of a component's task state: running is ok, an ended task is bad, anything else is on its way."""
    if state == "running":
        return "ok"
    return "bad" if state in ("failed", "rejected", "complete", "shutdown", "orphaned") else "warn"


#: The page's templates (files of :mod:`robocore.resources`): the page, and the part of it a look changes.
PAGE, FLEET = "fleet-page.html", "fleet-page-fleet.html"


@functools.cache
def _templates() -> jinja2.Environment:
    import jinja2

    from robocore import resources

    loader = jinja2.DictLoader({name: resources.read(name).decode() for name in (PAGE, FLEET)})
    env = jinja2.Environment(loader=loader, autoescape=True, undefined=jinja2.StrictUndefined, trim_blocks=True,
                             lstrip_blocks=True, keep_trailing_newline=True)
    env.filters.update(scrub=scrub, task_tone=task_tone)
    env.globals.update(verdict=verdict, rollout=rollout, runs=runs, groups=groups, waves=waves,
                       search_text=search_text, fold=fold)
    return env


def render_page(view: FleetView, *, live: bool = False) -> str:
    """The whole page of ``view``: one HTML document, CSS inline; ``live`` adds the few lines of script that fetch
    ``fleet`` (:func:`render_fleet`) every :data:`LIVE_INTERVAL` seconds and swap it in without a reload."""
    return _templates().get_template(PAGE).render(view=view, live=live, interval_ms=int(LIVE_INTERVAL * 1000))


def render_fleet(view: FleetView) -> str:
    """The part of the page a look changes (rollout, robots, releases): what the live page fetches again."""
    return _templates().get_template(FLEET).render(view=view)
