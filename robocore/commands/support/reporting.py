"""The one output path of every task: progress, messages, tables and plans for people, one JSON
document for programs.

A command gets a :class:`Reporter` from its options. Text for people goes through it: progress and
messages on stderr (:meth:`Reporter.info`, :meth:`Reporter.notice`), plans, tables and result lines
on stdout (:meth:`Reporter.plain`, :meth:`Reporter.out`, :meth:`Reporter.table`). Results are typed
objects (dataclasses) handed to :meth:`Reporter.add`. With ``--json`` nothing for people reaches
stdout; once the task ends, :meth:`Reporter.finish` (or :meth:`Reporter.fail`, with the error) prints
exactly one object::

    {"schema_version": 1, "task": "run", "ok": true,
     "results": [{"kind": "host_run", ...}, ...],
     "problems": [{"file": "robot.yaml", "line": 14, "key": "components[0].runs_on",
                   "message": "...", "severity": "error", "hint": null}, ...]}

Each result carries its ``kind`` and its fields; a problem that is not about a file has ``file``,
``line`` and ``key`` null. A streaming task (``logs --follow --json``) prints one object per line
instead (:meth:`Reporter.stream`), then the envelope as its last line.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from robocore.errors import ConfigError, GroupError, Problem, RobocoreError
from robocore.ui import bounded

#: Version of the JSON envelope; it changes only when a key changes meaning or goes away.
SCHEMA_VERSION = 1


def problem_dict(problem: Problem) -> dict[str, Any]:
    """A robot.yaml problem as the envelope writes it."""
    return {"file": problem.file, "line": problem.line, "key": bounded(problem.path) or None,
            "message": bounded(problem.message), "severity": problem.severity, "hint": None}


def error_problems(error: RobocoreError) -> list[dict[str, Any]]:
    """The problems of an error: a ConfigError's own, one per failed host of a GroupError, else one per
    line of the error (a ``hint:`` line becomes the hint of the problem before it)."""
    if isinstance(error, ConfigError):
        return [problem_dict(p) for p in error.problems]
    if isinstance(error, GroupError):
        found = []
        for host, failure in sorted(error.failures.items()):
            for item in error_problems(failure):
                found.append({**item, "message": f"{host}: {item['message']}"})
        return found
    found = []
    for line in error.lines():
        if line.startswith("hint: ") and found:
            found[-1]["hint"] = bounded(line.removeprefix("hint: "))
        else:
            found.append({"file": None, "line": None, "key": None, "message": bounded(line), "severity": "error",
                          "hint": None})
    return found


def as_result(result: Any) -> dict[str, Any]:
    """A typed result as the envelope writes it: its ``kind``, then its fields."""
    return {"kind": getattr(result, "kind", type(result).__name__.lower()), **dataclasses.asdict(result)}


@dataclass
class Outcome:
    """What happened to one image or one colcon build."""

    what: str  # image reference or component name
    role: str  # base | component | build
    action: str  # built | up-to-date | would-build | unknown (dry run) | failed
    reason: str = ""
    image_id: str | None = None
    seconds: float = 0.0
    packages: list[str] = field(default_factory=list)
    #: A dry run's plan: the Dockerfile of an image, the colcon command line or the copies of a build.
    plan: str | None = None

    @property
    def kind(self) -> str:
        """``build`` for a colcon build, ``image`` for an image."""
        return "build" if self.role == "build" else "image"


class Reporter:
    """Where a task's output goes: stderr and stdout for people, one JSON document with ``json``."""

    def __init__(self, task: str = "", *, json: bool = False, quiet: bool = False) -> None:
        self.task = task
        self.json = json
        self.quiet = quiet
        self.human = not quiet and not json
        self.results: list[Any] = []
        self.problems: list[dict[str, Any]] = []
        self.emitted = False
        self.streamed = False  # results went out as JSON Lines: the envelope follows as one line

    # ------------------------------------------------------------------ for people

    def info(self, message: str, *, markup: bool = False, style: str | None = None) -> None:
        """Progress or a message on stderr, unless quiet or JSON (rich markup only with ``markup``: the text
        may hold values from robot.yaml)."""
        if self.human:
            self.notice(message, markup=markup, style=style)

    def notice(self, message: str, *, markup: bool = False, style: str | None = None) -> None:
        """A message on stderr that is shown even when quiet (warnings, what could not be done)."""
        from robocore.ui import console

        console().print(bounded(message), markup=markup, style=style, soft_wrap=True)

    def warn(self, message: str, problem: Problem | None = None) -> None:
        """A warning: ``warning: message`` on stderr for people, a problem of severity warning in JSON."""
        if self.json:
            self.problems.append(problem_dict(problem) if problem is not None else {
                "file": None, "line": None, "key": None, "message": bounded(message), "severity": "warning",
                "hint": None})
        else:
            self.notice(str(problem) if problem is not None else f"warning: {message}")

    def plain(self, text: str) -> None:
        """Plan text (a dry run) on stdout, control characters escaped; not with JSON."""
        if not self.json:
            from robocore.ui import clean

            print(clean(text), flush=True)

    def out(self, text: str) -> None:
        """A result line on stdout (the rich console: control characters escaped); not with JSON."""
        if not self.json:
            from robocore.ui import stdout

            stdout().print(text, markup=False, soft_wrap=True)

    def table(self, table: Any) -> None:
        """A rich table on stdout; off a terminal (logs, CI, pipes) 160 columns wide, not squeezed into 80."""
        if not self.json:
            print_table(table)

    @contextmanager
    def progress(self) -> Iterator[Callable[[str, str], None]]:
        """``update(key, text)`` shows one live line per key while the block runs."""
        if not self.human:
            yield lambda key, text: None
            return
        from rich.markup import escape
        from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

        from robocore.ui import clean, console

        if not console().is_terminal:  # logs of CI: the build steps as plain lines

            def plain(key: str, text: str) -> None:
                if text.startswith(("Step ", "building")):
                    console().print(f"{key}: {text}", markup=False, highlight=False, soft_wrap=True)

            yield plain
            return
        tasks: dict[str, Any] = {}
        with Progress(SpinnerColumn(), TextColumn("{task.description}"), TimeElapsedColumn(),
                      console=console(), transient=True) as bar:

            def update(key: str, text: str) -> None:
                line = f"[bold]{key}[/]: {escape(clean(text))[:100]}"
                if key not in tasks:
                    tasks[key] = bar.add_task(line, total=None)
                else:
                    bar.update(tasks[key], description=line)

            yield update

    # ------------------------------------------------------------------ for programs

    def add(self, *results: Any) -> None:
        """Typed results (dataclasses) of the task, in order."""
        self.results.extend(results)

    def stream(self, result: Any) -> None:
        """One result as a line of JSON at once (streaming tasks with JSON)."""
        self.streamed = True
        print(json.dumps(as_result(result), default=str), flush=True)

    def finish(self) -> None:
        """The task ended without an error: with JSON, print the envelope (ok unless a problem is an error)."""
        self._emit(ok=not any(p["severity"] == "error" for p in self.problems))

    def fail(self, error: RobocoreError) -> None:
        """The task ended with ``error``: with JSON, print the envelope with its problems and ok false."""
        self.problems.extend(error_problems(error))
        self._emit(ok=False)

    def envelope(self, *, ok: bool) -> dict[str, Any]:
        """The one JSON document of the task."""
        return {"schema_version": SCHEMA_VERSION, "task": self.task, "ok": ok,
                "results": [as_result(r) for r in self.results], "problems": self.problems}

    def _emit(self, *, ok: bool) -> None:
        if not self.json or self.emitted:
            return
        self.emitted = True
        print(json.dumps(self.envelope(ok=ok), indent=None if self.streamed else 2, default=str), flush=True)


def print_table(table: Any) -> None:
    """Print a rich table on stdout; off a terminal (logs, CI, pipes) 160 columns wide, not squeezed into 80."""
    from robocore.ui import make_console, stdout

    out = stdout()
    if out.is_terminal:
        out.print(table)
        return
    make_console(file=sys.stdout, width=160).print(table)


def report_outcomes(report: Reporter, outcomes: Sequence[Outcome]) -> None:
    """Images and builds as results, and one line each for people: built (and how long), up to date..."""
    from rich.markup import escape

    report.add(*outcomes)
    for o in outcomes:
        mark = {"built": "[green]built[/]", "up-to-date": "[dim]up to date[/]",
                "would-build": "[yellow]would build[/]", "unknown": "[yellow]build or keep[/]",
                "failed": "[red]failed[/]"}.get(o.action, o.action)
        extra = f": {o.reason}" if o.action == "unknown" else f" ({o.reason})" if o.reason else ""
        secs = f" in {o.seconds:.1f}s" if o.action == "built" else ""
        report.info(f"{escape(o.what)}: {mark}{secs}{escape(extra)}", markup=True)
