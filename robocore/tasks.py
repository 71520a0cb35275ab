"""The invoke task collection: ``invoke <task>`` in a project, ``robocore <task>`` anywhere. Tasks are thin: flags,
load, then :mod:`robocore.commands`; every :class:`~robocore.errors.RobocoreError` becomes one line per problem on
stderr and an exit code here only (and in the ``--json`` document); heavy imports stay in the task bodies (a fast
``--help``). The project folder is the ``robocore.project`` setting (``-p DIR``), else the current folder; the
command line (for the ssh warm-up) is ``robocore.argv``, else invoke's own."""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from invoke.collection import Collection
from invoke.context import Context
from invoke.exceptions import Exit
from invoke.tasks import task

from robocore.errors import RobocoreError

if TYPE_CHECKING:
    from robocore.commands.support.context import Options

F = TypeVar("F", bound=Callable[..., Any])

#: The section of invoke's configuration that ``robocore`` fills in (``project``, ``argv``).
CONFIG_SECTION = "robocore"


def _setting(c: Context, key: str) -> Any:
    section = c.config.get(CONFIG_SECTION)
    return section.get(key) if section is not None else None


def project_dir(c: Context) -> Path:
    """The project folder: the ``robocore.project`` setting (``robocore -p DIR``), else the current folder."""
    configured = _setting(c, "project")
    return Path(configured) if configured else Path.cwd()


def command_line(c: Context) -> tuple[str, ...]:
    """The whole command line: the ``robocore.argv`` setting (``robocore`` sets it), else invoke's own
    (a project's ``invoke build sync run``)."""
    configured = _setting(c, "argv")
    return tuple(configured) if configured is not None else tuple(sys.argv[1:])


def reported(body: F) -> F:
    """Translate robocore errors into one line per problem and an exit code."""

    @functools.wraps(body)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return body(*args, **kwargs)
        except RobocoreError as error:
            from robocore.ui import bounded, clean

            for line in error.lines():
                print(clean(bounded(f"error: {line}" if not line.startswith("hint:") else line)), file=sys.stderr)
            raise Exit(code=error.exit_code) from None
        except KeyboardInterrupt:
            print("interrupted", file=sys.stderr)
            raise Exit(code=130) from None

    return wrapper  # type: ignore[return-value]


def _given(value: str | None, flag: str, *, required: bool = False) -> str | None:
    """An option's value: None when the option was not given; an empty (or blank) value is refused in one line,
    never read as "not given" (``down --host ""`` must not mean every host) nor as the current folder."""
    if value is not None and not value.strip():
        from robocore.errors import UsageError
        raise UsageError(f"{flag} was given an empty value; name one" + ("" if required else f" (or leave {flag} out)"))
    return value


def _require(component: str | None, task_name: str) -> str:
    component = _given(component, "--component")
    if component is None:
        from robocore.errors import UsageError
        raise UsageError(f"{task_name} needs --component NAME", hint=f"robocore {task_name} --component talker")
    return component


def _tag(tag: str | None) -> str | None:
    """``--tag``: None when not given, else a valid image tag (UsageError otherwise)."""
    tag = _given(tag, "--tag")
    if tag is None:
        return None
    from robocore.plan.naming import is_image_tag

    if not is_image_tag(tag):
        from robocore.errors import UsageError
        raise UsageError(f"--tag {tag!r} is not a valid image tag (a letter, digit or '_', then up to 127 "
                         "letters, digits, '_', '.' or '-')")
    return tag


#: Largest value of a counting flag (``logs --tail``): more lines than any container keeps.
MAX_COUNT = 10_000_000


def _count(value: str, flag: str) -> int:
    """A flag that takes a whole number from 0 to :data:`MAX_COUNT` (taken as text, so that invoke never fails
    on it, and a number of thousands of digits is refused before it is converted)."""
    text = value.strip()
    if not text.isdigit() or not text.isascii() or len(text) > len(str(MAX_COUNT)) or int(text) > MAX_COUNT:
        from robocore.errors import UsageError
        shown = value if len(value) <= 40 else value[:37] + "..."
        raise UsageError(f"{flag} takes a whole number from 0 to {MAX_COUNT:,} (got {shown!r})")
    return int(text)


def _options(c: Context, task_name: str, **flags: Any) -> Options:
    from robocore.commands.support.context import Options

    if "dry_run" in flags and _setting(c, "argv") is None and any(
            arg == "--dry-run" or arg.startswith("--dry-run=") for arg in command_line(c)):
        flags["dry_run"] = True  # a project's own `invoke build sync run --dry-run`: the whole line is a dry run

    return Options(project_dir=project_dir(c), argv=command_line(c), task=task_name, **flags)


def _execute(options: Options, step: Callable[[], Any]) -> Any:
    """Run a task's ``step``; its reporter then prints the JSON document (with ``--json``): the results, or
    the error's problems with ok false. The error itself goes on to :func:`reported`."""
    try:
        result = step()
    except RobocoreError as error:
        options.report.fail(error)
        raise
    except KeyboardInterrupt:
        options.report.fail(RobocoreError("interrupted"))
        raise
    options.report.finish()
    return result


@task(help={"dry_run": "Only print what would be checked.", "json": "Machine-readable result on stdout."})
@reported
def validate(c: Context, dry_run: bool = False, json: bool = False) -> None:
    """Check robot.yaml: every problem, one line each, with file, line and key."""
    from robocore.commands import validate as command

    options = _options(c, "validate", dry_run=dry_run, json=json)
    _execute(options, lambda: command.run(options))


@task(
    help={
        "defaults": "Use default answers, ask nothing.",
        "distro": "ROS distribution (ROS 1: noetic, melodic; ROS 2: humble, jazzy, kilted, rolling).",
        "base": "Base image kind: official, wheels (ROS 2 from PyPI) or debian (ROS 1 from Debian).",
        "dry_run": "Only print what would be written.",
        "source": "Template source: a robocore git repository (path or URL) or a template folder "
                  "(default: robocore's own repository at its version tag, else the bundled template).",
        "ref": "Git tag or commit to render (default: v<robocore version>; with --source: its latest tag).",
    },
    optional=[],
)
@reported
def init(
    c: Context, path: str, defaults: bool = False, distro: str | None = None, base: str | None = None,
    dry_run: bool = False, source: str | None = None, ref: str | None = None,
) -> None:
    """Create a robot project in PATH from the copier template."""
    from robocore.commands import init as command

    command.run(Path(_given(path, "PATH") or "."), defaults=defaults, distro=_given(distro, "--distro"),
                base=_given(base, "--base"), dry_run=dry_run, source=_given(source, "--source"),
                ref=_given(ref, "--ref"))


@task(help={"fleet": "The schema of the fleet file (fleet.yaml) instead of robot.yaml's."})
def schema(c: Context, fleet: bool = False) -> None:
    """Print the JSON Schema of robot.yaml (of fleet.yaml with --fleet)."""
    from robocore.config.schema import schema_json
    print(schema_json(fleet=fleet))


@task(name="prepare-base", help={"force": "Rebuild even if inputs are unchanged.", "dry_run": "Print the plan only.",
                                 "quiet": "Only errors.", "json": "Machine-readable result on stdout."})
@reported
def prepare_base(
    c: Context, force: bool = False, dry_run: bool = False, quiet: bool = False, json: bool = False
) -> None:
    """Build the base image: ROS distro + common_packages; only when its inputs changed."""
    from robocore.commands import prepare_base as command

    options = _options(c, "prepare-base", dry_run=dry_run, quiet=quiet, json=json)
    _execute(options, lambda: command.prepare_base(options, force=force))


@task(help={"refresh": "Only rewrite the per-host compose files.", "component": "Stage only this component.",
            "force": "Rebuild even if inputs are unchanged.", "dry_run": "Print the plan only.",
            "quiet": "Only errors.", "json": "Machine-readable result on stdout."})
@reported
def stage(c: Context, refresh: bool = False, component: str | None = None, force: bool = False,
          dry_run: bool = False, quiet: bool = False, json: bool = False) -> None:
    """Build one image per component (dependencies, no user code) and write compose files."""
    from robocore.commands import stage as command

    options = _options(c, "stage", dry_run=dry_run, quiet=quiet, json=json)
    _execute(options, lambda: command.stage(
        options, refresh=refresh, component=_given(component, "--component"), force=force))


@task(help={"component": "Build only this component.", "dry_run": "Print the plan only.",
            "full": "Always run colcon, even for edits that only change files colcon copies as they are.",
            "quiet": "Only errors.", "json": "Machine-readable result on stdout."})
@reported
def build(c: Context, component: str | None = None, full: bool = False, dry_run: bool = False, quiet: bool = False,
          json: bool = False) -> None:
    """colcon-build each component's workspace inside its staged image."""
    from robocore.commands import build as command

    options = _options(c, "build", dry_run=dry_run, quiet=quiet, json=json)
    _execute(options, lambda: command.build(options, component=_given(component, "--component"), full=full))


@task(help={"component": "Test only this component.",
            "packages_select": "Test only this package (repeat for more).", "dry_run": "Print the plan only.",
            "no_build": "Do not build what is stale first: refuse to test an out-of-date build instead.",
            "quiet": "Only errors.", "json": "Machine-readable result on stdout."},
      iterable=["packages_select"])
@reported
def test(c: Context, component: str | None = None, packages_select: list[str] | None = None, dry_run: bool = False,
         no_build: bool = False, quiet: bool = False, json: bool = False) -> None:
    """Build what is stale, then colcon-test each component's packages inside its staged image; one result per
    package (exit 9 on failure)."""
    from robocore.commands import test as command

    options = _options(c, "test", dry_run=dry_run, quiet=quiet, json=json)
    _execute(options, lambda: command.test(options, component=_given(component, "--component"),
                                                 packages=[_given(p, "--packages-select") or ""
                                                           for p in packages_select or []],
                                                 build_first=not no_build))


@task(help={"component": "Build and watch only this component (default: every component with a folder).",
            "dry_run": "Print the plans of build, sync and run once; watch nothing.",
            "quiet": "Only errors and one line per deploy."})
@reported
def dev(c: Context, component: str | None = None, dry_run: bool = False, quiet: bool = False) -> None:
    """build, sync and run, then again on every save (quick saves coalesce); a failed build leaves the robot on
    the last good release and says why in one line. Ctrl-C stops."""
    from robocore.commands import dev as command

    options = _options(c, "dev", dry_run=dry_run, quiet=quiet)
    command.dev(options, component=_given(component, "--component"))


@task(help={"host": "Sync only this host.", "dry_run": "Print the rsync commands only.", "quiet": "Only errors.",
            "json": "Machine-readable result on stdout."})
@reported
def sync(c: Context, host: str | None = None, dry_run: bool = False, quiet: bool = False, json: bool = False) -> None:
    """Copy compiled install trees and runtime files to each host; only what changed."""
    from robocore.commands import sync as command

    options = _options(c, "sync", dry_run=dry_run, quiet=quiet, json=json)
    _execute(options, lambda: command.sync(options, host=_given(host, "--host")))


@task(help={"host": "Start/restart only this host.", "tag": "Deploy this released version.",
            "dry_run": "Print the container plan only.", "quiet": "Only errors.", "json": "Machine-readable result."})
@reported
def run(
    c: Context, host: str | None = None, tag: str | None = None, dry_run: bool = False, quiet: bool = False,
    json: bool = False,
) -> None:
    """(Re)start each host's containers and the discovery server."""
    from robocore.commands import run as command

    options = _options(c, "run", dry_run=dry_run, quiet=quiet, json=json)
    _execute(options, lambda: command.run(options, host=_given(host, "--host"), tag=_tag(tag)))


@task(help={"host": "Stop only this host.", "dry_run": "Print what would be removed.", "quiet": "Only errors."})
@reported
def down(c: Context, host: str | None = None, dry_run: bool = False, quiet: bool = False) -> None:
    """Stop and remove the robot's containers."""
    from robocore.commands import down as command

    options = _options(c, "down", dry_run=dry_run, quiet=quiet)
    _execute(options, lambda: command.down(options, host=_given(host, "--host")))


@task(help={"json": "Machine-readable output.", "dry_run": "Print what would be queried.",
            "nodes": "Also list the live ROS nodes (listens to the graph for 3 s)."})
@reported
def status(c: Context, json: bool = False, dry_run: bool = False, nodes: bool = False) -> None:
    """Table of components (host, state, uptime, restarts, image); with --nodes the live ROS nodes too."""
    from robocore.commands import status as command

    options = _options(c, "status", json=json, dry_run=dry_run)
    _execute(options, lambda: command.status(options, nodes_too=nodes))


@task(help={"component": "Only this component.", "follow": "Keep following.",
            "tail": "Lines per container (a whole number; default 100).", "dry_run": "Print what would be read.",
            "json": "Machine-readable result on stdout (with --follow: one JSON object per line)."})
@reported
def logs(c: Context, component: str | None = None, follow: bool = False, tail: str = "100", dry_run: bool = False,
         json: bool = False) -> None:
    """Logs of the robot's containers on all hosts, each line prefixed by its component."""
    from robocore.commands import logs as command

    options = _options(c, "logs", dry_run=dry_run, json=json)
    _execute(options, lambda: command.logs(options, component=_given(component, "--component"), follow=follow,
                                           tail=_count(tail, "--tail")))


@task(help={"component": "The component to open a shell in (required).", "cmd": "Run this instead of a shell.",
            "new": "Start another container instead of joining a running one.",
            "devices": "'all' to pass every device of /dev.", "gpus": "Force GPUs on.", "no_gpus": "Force GPUs off.",
            "privileged": "Run privileged.", "dry_run": "Print the container spec only."})
@reported
def shell(c: Context, component: str | None = None, cmd: str | None = None, new: bool = False,
          devices: str | None = None, gpus: bool = False, no_gpus: bool = False, privileged: bool = False,
          dry_run: bool = False) -> None:
    """Interactive dev container in a component's environment (source mounted, ROS sourced)."""
    component = _require(component, "shell")
    from robocore.commands import shell as command

    options = _options(c, "shell", dry_run=dry_run)
    code = _execute(options, lambda: command.run(
        options, component=component, cmd=_given(cmd, "--cmd"), new=new, devices=_given(devices, "--devices"),
        gpus=True if gpus else (False if no_gpus else None), privileged=privileged))
    if code:
        raise Exit(code=code)


@task(help={"component": "The component whose live container to enter (required).",
            "cmd": "Run this instead of a shell.", "dry_run": "Print what would be run."})
@reported
def connect(c: Context, component: str | None = None, cmd: str | None = None, dry_run: bool = False) -> None:
    """Shell inside the running container of a component on its host, as a ROS super client."""
    component = _require(component, "connect")
    from robocore.commands import connect as command

    options = _options(c, "connect", dry_run=dry_run)
    code = _execute(options, lambda: command.connect(options, component=component, cmd=_given(cmd, "--cmd")))
    if code:
        raise Exit(code=code)


@task(help={"tag": "Version (default: git describe).", "dry_run": "Print what would be pushed.",
            "fleet": "Self-contained images for fleet.yaml's robots (install trees inside), recorded by digest in "
                     ".robocore/releases/V.json.",
            "json": "Machine-readable result on stdout."})
@reported
def release(c: Context, tag: str | None = None, dry_run: bool = False, fleet: bool = False,
            json: bool = False) -> None:
    """Tag every image with a version and push it to the registry (--fleet: images a fleet runs, by digest)."""
    options = _options(c, "release", dry_run=dry_run, json=json)
    if fleet:
        from robocore.commands import fleet_release

        _execute(options, lambda: fleet_release.release_fleet(options, tag=_tag(tag)))
        return
    from robocore.commands import release as command

    _execute(options, lambda: command.release(options, tag=_tag(tag)))


@task(help={"host": "Only this host.", "dry_run": "Print what would be done."})
@reported
def rollback(c: Context, host: str | None = None, dry_run: bool = False) -> None:
    """Return each host to the version it ran before the last run."""
    from robocore.commands import rollback as command

    options = _options(c, "rollback", dry_run=dry_run)
    _execute(options, lambda: command.rollback(options, host=_given(host, "--host")))


@task(
    help={
        "engine": "What to export for: kubernetes (kustomize, Rancher Fleet, Argo CD).",
        "path": "The folder to write: new, empty, or written by an earlier export (only its files are replaced).",
        "tag": "The release whose images the robots run (robocore release --tag V).",
        "git_repo": "The git repository the GitOps controllers pull from (default: fleet.yaml's gitops.repo).",
        "git_path": "The folder's path inside that repository (default: fleet.yaml's gitops.path, else its top).",
        "model": "Another project (its robot.yaml and fleet.yaml) to export with this one; repeatable.",
        "dry_run": "Only list the files that would be written.",
        "json": "Machine-readable result on stdout.",
    },
    iterable=["model"],
)
@reported
def export(c: Context, engine: str, path: str, tag: str | None = None, git_repo: str | None = None,
           git_path: str | None = None, model: list[str] | None = None, dry_run: bool = False,
           json: bool = False) -> None:
    """Write the robot, or the fleet of fleet.yaml, as Kubernetes objects for k3s, Rancher Fleet and Argo CD."""
    from robocore.commands import export as command
    from robocore.errors import UsageError

    if engine != "kubernetes":
        raise UsageError(f"unknown export {engine!r} (known: kubernetes)", hint="robocore export kubernetes DIR")
    options = _options(c, "export", dry_run=dry_run, json=json)
    folder = Path(_given(path, "DIR", required=True) or "")  # "" would be read as the current folder
    models = [Path(_given(m, "--model", required=True) or "") for m in model or []]
    repository = _given(git_repo, "--git-repo")
    inside = _given(git_path, "--git-path")
    _execute(options, lambda: command.export_kubernetes(options, folder, tag=_tag(tag), git_repo=repository,
                                                        git_path=inside, models=models))


@task(help={"host": "Only this host.", "json": "Machine-readable result on stdout."})
@reported
def doctor(c: Context, host: str | None = None, json: bool = False) -> None:
    """Check every host: reachable, Docker version, arch, free disk, rsync."""
    from robocore.commands import doctor as command

    options = _options(c, "doctor", json=json)
    _execute(options, lambda: command.doctor(options, host=_given(host, "--host")))


@task(name="desktop-password")
@reported
def desktop_password(c: Context) -> None:
    """Print the project's VNC password (made once, kept 0600 in .robocore/desktop/), which noVNC asks for."""
    from robocore.commands import desktop_password as command
    options = _options(c, "desktop-password")
    print(_execute(options, lambda: command.desktop_password(options.load())))


@task(iterable=["robot"], help={"verb": "join|rollout|status|rollback|page|logs|connect", "robot": "this robot",
                                "out": "page: write DIR/index.html", "serve": "page: serve it live (read-only)",
                                "component": "logs: only this one", "follow": "logs: live"})
@reported
def fleet(c: Context, verb: str = "", version: str | None = None, robot: list[str] | None = None, dry_run: bool = False,
          json: bool = False, out: str | None = None, serve: bool = False, port: str | None = None,
          bind: str | None = None, force: bool = False, component: str | None = None, follow: bool = False) -> None:
    """The fleet on Docker Swarm: join, rollout VERSION [--force], status, rollback [ROBOT...], page, logs, connect."""
    from robocore.commands import fleet as command
    code = _execute(options := _options(c, f"fleet-{verb}", dry_run=dry_run, json=json), lambda: command.fleet(
        options, verb=verb, version=_tag(version), robots=robot or [], page=command.page_flags(out, serve, port, bind),
        force=force, component=_given(component, "--component"), follow=follow))
    if verb == "connect" and code:
        raise Exit(code=code)  # the shell's own exit code


PROJECT_TASKS = (validate, prepare_base, stage, build, test, dev, sync, run, down, status, logs, shell, connect,
                 release, rollback, export, doctor, desktop_password, fleet)

#: The collection a project's tasks.py re-exports (``from robocore.tasks import namespace``).
namespace = Collection(*PROJECT_TASKS)
#: The collection of the ``robocore`` command: the project tasks plus init and schema.
cli_namespace = Collection(init, schema, *PROJECT_TASKS)
