"""The ``robocore`` command.

``robocore [-p PROJECT] TASK [flags]``, ``robocore --project=PROJECT TASK`` and the short
form ``robocore PROJECT TASK [flags]`` run the same invoke tasks a project's ``invoke``
runs, from any folder. The project folder and the command line reach the tasks as invoke
settings (``robocore.project``, ``robocore.argv``), at the level of command-line overrides.
Start-up stays light: only invoke and the task surface are imported before a task runs
(pydantic, docker-py and copier load inside the tasks), and a command with remote steps
starts its ssh connections first (:mod:`robocore.commands.support.warmup`).
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Sequence

from robocore import __version__

TYPE_CHECKING = False  # typing's constant, without importing typing on the no-op memo's path (12M instructions)
if TYPE_CHECKING:
    from typing import Any

PROJECT_FLAGS = ("-p", "--project")
#: invoke core flags that take a separate value (``-f FILE``), so the value is not taken for a project.
VALUE_FLAGS = frozenset({
    "-f", "--config", "-T", "--command-timeout", "-D", "--list-depth", "-F", "--list-format", "--hide",
    "--print-completion-script",
})


#: The tasks whose no-op may answer from :mod:`robocore.commands.support.noop`'s memo (the module decides; this only
#: spares other command lines its import).
MEMO_TASKS = frozenset({"validate", "stage", "build"})


class CommandLineError(Exception):
    """The ``robocore`` command line itself is malformed (before any task runs)."""


def split_project(argv: Sequence[str], task_names: set[str]) -> tuple[str | None, list[str]]:
    """Pull the project folder out of ``argv``: ``-p DIR``, ``--project=DIR`` or a leading ``DIR TASK``.

    Only the part before the first task name is searched, so task flags (``shell -p`` is
    ``--privileged``) are left alone. Raises :class:`CommandLineError` for ``-p`` without a folder.
    """
    args = list(argv)
    project: str | None = None
    rest: list[str] = []
    i = 0
    while i < len(args):
        arg = args[i]
        if arg in PROJECT_FLAGS:
            if i + 1 >= len(args) or not args[i + 1]:
                raise CommandLineError(f"{arg} needs a project folder")
            project = args[i + 1]
            i += 2
            continue
        if arg.startswith("--project="):
            project = arg.split("=", 1)[1]
            if not project:
                raise CommandLineError("--project= needs a project folder")
            i += 1
            continue
        if arg in VALUE_FLAGS:
            rest.extend(args[i:i + 2])
            i += 2
            continue
        if arg.startswith("-"):
            rest.append(arg)
            i += 1
            continue
        if arg in task_names:
            rest.extend(args[i:])
            break
        following = args[i + 1] if i + 1 < len(args) else None
        if project is None and (following in task_names or (following is None and os.path.isdir(arg))):
            project = arg
            i += 1
            continue
        rest.extend(args[i:])
        break
    return project, rest


def config_file_problem(rest: Sequence[str]) -> str | None:
    """Why the invoke configuration file named by ``-f FILE``/``--config FILE`` cannot be read (a FIFO would
    block invoke's read for ever, a folder or device fail with a traceback), else None. Only invoke's own
    flags, before the first task, are read: a task's ``-f`` (``logs -f``) is that task's flag."""
    import stat

    i = 0
    while i < len(rest):
        flag = rest[i]
        value = rest[i + 1] if i + 1 < len(rest) else None
        if not flag.startswith("-"):
            break  # the first task: what follows belongs to the tasks
        i += 2 if flag in VALUE_FLAGS else 1
        name = value if flag in ("-f", "--config") else flag.split("=", 1)[1] if flag.startswith("--config=") else None
        if name is None:
            continue
        try:
            mode = os.stat(name).st_mode
        except (OSError, ValueError) as exc:
            return f"{flag} {name!r}: cannot be read ({getattr(exc, 'strerror', None) or exc})"
        if not stat.S_ISREG(mode):
            return f"{flag} {name!r}: is not a regular file (a folder, FIFO or device)"
    return None


def init_in_project(rest: list[str], project: str) -> list[str]:
    """``robocore DIR init`` (and ``robocore -p DIR init``): create the project in DIR."""
    if rest[:1] != ["init"] or any(arg == "--path" or arg.startswith("--path=") for arg in rest):
        return rest
    return ["init", f"--path={project}", *rest[1:]]


#: The values of invoke's ``--list-format``.
LIST_FORMATS = ("flat", "nested", "json")
#: What a malformed command line is told, after invoke's own words.
USAGE_HINT = "robocore --help lists the tasks, robocore TASK --help their flags"


def _usage_error(message: str) -> Any:
    """invoke's Exit carrying one escaped line and exit code 2 (Program.run prints it and exits)."""
    from invoke.exceptions import Exit

    from robocore.ui import bounded, clean

    text = " ".join(clean(bounded(message)).split("\n"))
    return Exit(message=f"robocore: {text} ({USAGE_HINT})", code=2)


#: The flag that makes a whole command line a dry run (as invoke names it in a task's parser context).
DRY_RUN = "dry-run"


def dry_run_for_the_line(contexts: Sequence[Any]) -> None:
    """``--dry-run`` given to any task of a line with several (``robocore build sync run --dry-run``) applies to
    every task of it: invoke gives a flag to the task it follows, and a line that says dry run must never
    deploy. A task of such a line that has no dry run (``doctor``) makes the line a one-line usage error."""
    if len(contexts) < 2 or not any(DRY_RUN in ctx.args and ctx.args[DRY_RUN].value for ctx in contexts):
        return
    lacking = [ctx.name for ctx in contexts if DRY_RUN not in ctx.args]
    if lacking:
        raise _usage_error(f"--dry-run applies to every task of the line, and {', '.join(lacking)} has no dry run; "
                           "run it on a line of its own")
    for ctx in contexts:
        ctx.args[DRY_RUN].value = True


def _one_line(step: Any) -> Any:
    """A parse step of invoke's Program whose parse errors (and a flag value invoke cannot convert, such as
    ``-D abc``) become one line and exit code 2 instead of invoke's exit code 1 or a traceback."""
    from invoke.exceptions import ParseError

    def wrapped(self: Any, *args: Any) -> Any:
        try:
            return step(self, *args)
        except ParseError as error:
            raise _usage_error(str(error)) from None
        except ValueError as error:
            from robocore.ui import plain_words

            raise _usage_error(f"a flag's value is not valid: {plain_words(str(error))}") from None

    return wrapped


def _program(namespace: Any, settings: dict[str, Any] | None = None) -> Any:
    """An invoke Program named robocore whose help documents ``-p/--project`` (instead of invoke's ``--pty``),
    whose command-line errors are one line with exit code 2, and whose tasks find ``settings`` in their
    configuration's ``robocore`` section (beside the other command-line overrides)."""
    from invoke.config import Config, copy_dict, merge_dicts
    from invoke.parser.argument import Argument
    from invoke.program import Program

    class RobocoreConfig(Config):
        def load_overrides(self, data: dict[str, Any], merge: bool = True) -> None:
            super().load_overrides(merge_dicts(copy_dict(data), {"robocore": settings or {}}), merge=merge)

    class RobocoreProgram(Program):
        parse_core = _one_line(Program.parse_core)

        @_one_line
        def parse_cleanup(self) -> None:
            chosen = self.args["list-format"].value
            if chosen not in LIST_FORMATS:  # invoke would fail with a traceback
                raise _usage_error(f"--list-format {chosen!r}: choose one of {', '.join(LIST_FORMATS)}")
            super().parse_cleanup()

        @_one_line
        def parse_tasks(self) -> None:
            super().parse_tasks()
            dry_run_for_the_line(self.tasks)
            remainder = self.core.remainder if self.core is not None else ""
            if remainder.strip():
                raise _usage_error(f"robocore tasks take no arguments after '--' (got {remainder!r})")

        def core_args(self) -> list[Argument]:
            args = [a for a in super().core_args() if "pty" not in a.names]
            args.append(Argument(names=("pty",), kind=bool, default=False, help="Use a pty for shell commands."))
            args.append(Argument(
                names=("project", "p"),
                help="The robot project folder (default: the current folder). Also: robocore DIR TASK.",
            ))
            return args

        def print_help(self) -> None:
            print("robocore [-p DIR] TASK [--task-opts] ...  run TASK on the robot project in DIR (default: .)")
            print("robocore DIR TASK [--task-opts] ...       the same (robocore DIR init creates DIR)")
            print()
            super().print_help()

    return RobocoreProgram(namespace=namespace, version=__version__, name="robocore", binary="robocore",
                           config_class=RobocoreConfig)


def _run_recording(memo: Any, args: list[str]) -> None:
    """Run a memoisable command line, printing as usual; a success that changed nothing is memoised."""
    from robocore.commands.support import noop

    with noop.captured() as (out, err):
        try:
            main(args)
        except SystemExit as done:
            if done.code not in (0, None):
                raise
    with contextlib.suppress(OSError):  # no memo then: the next run takes the ordinary path again
        memo.record(out.kept.getvalue(), err.kept.getvalue())


#: ``robocore fleet join|rollout|status|rollback|page ...``: the ``fleet`` task, its verb a flag.
FLEET_WORD = "fleet"
FLEET_VERBS = ("join", "rollout", "status", "rollback", "page", "logs", "connect")
#: The fleet task's flags that take a value as the next word (``logs r1 --component talker``).
FLEET_VALUE_FLAGS = frozenset({"--component", "--out", "--port", "--bind", "--version", "--robot"})
#: ``robocore fleet --help`` (and ``fleet VERB --help``): the commands as they are typed, not the task's flags.
FLEET_USAGE = """\
Usage: robocore [-p DIR] fleet COMMAND [--dry-run] [--json]

  join                   the swarm on the manager, every host of every robot joined and labelled
  rollout VERSION        release VERSION (made by release --fleet --tag VERSION) wave by wave,
                         each robot behind the health gate; a robot that fails goes back;
                         a robot is asked first (update lock, maintenance window): --force does not ask
  status                 every robot: online or offline, the release it runs and its target, health
  rollback [ROBOT...]    robots back to the release each ran before (default: every robot)
  page --out DIR         the fleet page as one HTML file (opens offline)
  page --serve [--port N] [--bind ADDR]
                         the fleet page served live, read-only (127.0.0.1:8765 by default)
  logs ROBOT [--component C] [--follow]
                         a robot's logs through the manager (no connection to the robot)
  connect ROBOT COMPONENT
                         a shell in the component's live container (found through the manager,
                         entered through the robot host's daemon, as robocore connect does)

  --dry-run              say what would be done and how the manager is reached; contact nothing
  --json                 the results as JSON on stdout

fleet.yaml names the manager, the registry and the robots: see docs/fleets.md."""


def fleet_task(rest: list[str]) -> list[str]:
    """``fleet VERB ...`` as the ``fleet`` task's flags: ``--verb VERB``; ``rollout VERSION`` gives ``--version
    VERSION``, ``rollback ROBOT...`` and ``logs ROBOT`` one ``--robot ROBOT`` each, ``connect ROBOT COMPONENT``
    ``--robot ROBOT --component COMPONENT`` (operands after ``--`` too). Other command lines are kept."""
    if len(rest) < 2 or rest[0] != FLEET_WORD or rest[1].startswith("-"):
        return rest
    verb, args = rest[1], rest[2:]
    if verb not in FLEET_VERBS:
        raise CommandLineError(f"unknown fleet command {verb!r} (fleet {'|'.join(FLEET_VERBS)})")
    out = [FLEET_WORD, "--verb", verb]
    operand_flag = {"rollout": "--version", "rollback": "--robot", "logs": "--robot", "connect": "--robot"}.get(verb)
    operands = 0
    operands_only = value_next = False
    for arg in args:
        if arg == "--" and not operands_only:
            operands_only = True
        elif operand_flag is not None and (operands_only or not arg.startswith("-")) and not value_next:
            if verb == "connect":  # connect ROBOT COMPONENT
                if operands == 2:
                    raise CommandLineError(f"fleet connect takes one robot and one component (got {arg!r} too)")
                operand_flag = ("--robot", "--component")[operands]
            out += [operand_flag, arg]
            operands += 1
        else:
            out.append(arg)
            value_next = arg in FLEET_VALUE_FLAGS
    return out


def main(argv: Sequence[str] | None = None) -> None:
    """Entry point of the ``robocore`` console script. Output piped into a reader that stopped early
    (``robocore fleet --help | head``) ends the command quietly with status 1, whichever path printed it."""
    try:
        _main(argv)
    except BrokenPipeError:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # Python's own flush at exit would fail on the closed pipe again
        sys.exit(1)


def _main(argv: Sequence[str] | None) -> None:
    args = list(sys.argv[1:] if argv is None else argv)
    memo = None
    if argv is None and MEMO_TASKS & set(args[:3]):  # an unchanged project's no-op answers from its memo
        from robocore.commands.support import noop

        memo = noop.for_command(args)
        if memo is not None and memo.replay(sys.stdout, sys.stderr):
            return
    if argv is None and "status" in args[:4]:  # an unchanged all-local project's status answers from its memo
        from robocore.commands.support import status_memo

        if status_memo.answer(args):
            return
    if argv is None:  # a real command line: start the robot hosts' ssh handshakes while the rest loads
        from robocore.commands.support.warmup import warm_recorded

        warm_recorded(args)
    if memo is not None:
        _run_recording(memo, args)
        return
    from robocore.tasks import cli_namespace

    names = set(cli_namespace.task_names) | {n.replace("_", "-") for n in cli_namespace.task_names}
    try:
        project, rest = split_project(args, names)
        if rest[:1] == [FLEET_WORD] and {"-h", "--help"} & set(rest):
            print(FLEET_USAGE)
            return
        rest = fleet_task(rest)
    except CommandLineError as error:
        from robocore.ui import bounded, clean

        print(f"robocore: {clean(bounded(str(error)))} (robocore -p DIR TASK, robocore DIR TASK)", file=sys.stderr)
        sys.exit(2)
    problem = config_file_problem(rest)
    if problem is not None:
        from robocore.ui import bounded, clean

        print(f"robocore: {clean(bounded(problem))} ({USAGE_HINT})", file=sys.stderr)
        sys.exit(2)
    # the steps that follow decide the ssh warm-up: only a real command line warms anything
    settings: dict[str, Any] = {"argv": args if argv is None else []}
    if project is not None:
        settings["project"] = os.path.abspath(project)
        rest = init_in_project(rest, project)
    _program(cli_namespace, settings).run(["robocore", *rest])


if __name__ == "__main__":
    main()
