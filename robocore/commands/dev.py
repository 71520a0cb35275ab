"""dev: watch the workspaces and redeploy on save, in one long-lived process.

``robocore dev [--component C]`` runs ``build`` (incremental: only what changed is rebuilt), ``sync``
and ``run``, then watches the component folders and ``robot.yaml``: a save starts the same
deploy again. What the one-shot loop ``build sync run`` pays on every edit is paid once here:
Python's start-up and imports (pydantic, docker-py, rich), loading the project, and the ssh
handshake while the connection stays in use.

Saves in quick succession coalesce: a deploy starts once the watched files have not changed
for :data:`SETTLE` seconds. Each step keeps its guarantees, since each is the task itself: a
build that fails stops the deploy before ``sync``, so the robot keeps running the last good
release, and the loop says why in one line and goes on watching; ``sync`` switches each
release atomically and ``run`` replaces only what changed.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from robocore.commands import build, run, sync
from robocore.commands.support import noop
from robocore.commands.support.context import Options
from robocore.commands.support.workspace import selected_components
from robocore.errors import RobocoreError
from robocore.ui import clean

#: Seconds between two looks at the watched files, at least: a save is noticed within this, on average within half.
POLL = 0.01
#: A look at the watched files stats every file under them: the pause after a look is this many times what it took,
#: so that watching a large workspace costs about a tenth of a core, not a whole one.
POLL_COST_RATIO = 9
#: Seconds between two looks, at most (a workspace so large that one look takes 50 ms).
POLL_MAX = 0.5
#: Seconds the watched files must stay unchanged before a deploy starts (quick saves coalesce). An editor's save,
#: a "save all" or a formatter run on save writes its files within milliseconds of each other; 50 ms is also
#: watchexec's default debounce.
SETTLE = 0.05


def watched(options: Options, component: str | None) -> list[Path]:
    """What to watch: robot.yaml and each selected component's folder."""
    project = options.load()
    folders = [project.root / str(c.folder) for c in selected_components(project, component) if c.folder is not None]
    return [project.root / "robot.yaml", *folders]


def deploy(project_dir: Path, components: Sequence[str], *, quiet: bool,
           say: Callable[[str], None], dry_run: bool = False) -> dict[str, float] | None:
    """``build`` (each of ``components``, or all when empty), then ``sync`` and ``run``: the seconds each took,
    or None (and one line said) when a step failed: nothing after it ran."""
    argv = ("build", "sync", "run")
    seconds: dict[str, float] = {}

    def options(task: str) -> Options:
        seconds[task] = time.monotonic()
        return Options(project_dir=project_dir, quiet=quiet, argv=argv, task=task, dry_run=dry_run)

    step = "build"
    try:
        names: list[str | None] = [*components] or [None]
        for name in names:
            build.build(options("build"), component=name)
        step = "sync"
        sync.sync(options("sync"), host=None)
        step = "run"
        run.run(options("run"), host=None, tag=None)
        seconds["end"] = time.monotonic()
    except RobocoreError as error:
        first = (next(iter(error.lines()), str(error)).splitlines() or [""])[0]  # one line, log tails left out
        kept = "the robot keeps running the last good release" if step != "run" else "run did not finish"
        say(clean(f"dev: {step} failed: {first} ({kept}; watching for the next save)"))
        return None
    marks = sorted(seconds.items(), key=lambda item: item[1])
    return {name: later - at for (name, at), (_, later) in itertools.pairwise(marks)}


def poll_pause(look: float, least: float = POLL) -> float:
    """Seconds to wait before the next look at the watched files, when the last one took ``look`` seconds: ``least``
    for a small workspace, longer for one whose look is costly (:data:`POLL_COST_RATIO`), :data:`POLL_MAX` at most."""
    return min(max(least, look * POLL_COST_RATIO), max(least, POLL_MAX))


def dev(options: Options, *, component: str | None, say: Callable[[str], None] = print,
        rounds: int | None = None, poll: float = POLL, settle: float = SETTLE) -> None:
    """Deploy, then deploy again after each (coalesced) save, until interrupted (or after ``rounds`` deploys
    following the first, for tests). A dry run prints the plans of the first deploy's steps and returns."""
    selected = [component] if component else []
    if options.dry_run:
        deploy(options.project_dir, selected, quiet=options.quiet, say=say, dry_run=True)
        return
    paths = watched(options, component)
    current = noop.folders_digest(paths, options.project_dir)
    deploy(options.project_dir, selected, quiet=options.quiet, say=say)
    say("dev: watching " + ", ".join(str(p) for p in paths) + " (Ctrl-C stops)")
    done = 0
    pause = poll
    while rounds is None or done < rounds:
        time.sleep(pause)
        looked = time.monotonic()
        seen = noop.folders_digest(paths, options.project_dir)
        pause = poll_pause(time.monotonic() - looked, poll)
        if seen == current:
            continue
        while True:  # coalesce: wait until the files stay the same for `settle` seconds
            time.sleep(settle)
            later = noop.folders_digest(paths, options.project_dir)
            if later == seen:
                break
            seen = later
        current = seen
        started = time.monotonic()
        steps = deploy(options.project_dir, selected, quiet=options.quiet, say=say)
        done += 1
        if steps is not None:
            detail = ", ".join(f"{name} {secs:.2f}" for name, secs in steps.items())
            say(f"dev: deployed in {time.monotonic() - started:.2f} s ({detail})")
