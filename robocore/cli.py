"""The ``robocore`` command.

``robocore [-p PROJECT] TASK [flags]`` and the seed's form ``robocore PROJECT TASK [flags]``
run the same invoke tasks a project's ``invoke`` runs, from any folder.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence

from robocore import __version__

PROJECT_FLAGS = ("-p", "--project")


def split_project(argv: Sequence[str], task_names: set[str]) -> tuple[str | None, list[str]]:
    """Pull the project folder out of ``argv``: ``-p DIR``, ``--project=DIR`` or a leading ``DIR TASK``."""
    args = list(argv)
    project: str | None = None
    rest: list[str] = []
    i = 0
    while i < len(args):
        arg = args[i]
        if arg in PROJECT_FLAGS and i + 1 < len(args):
            project = args[i + 1]
            i += 2
            continue
        if arg.startswith("--project="):
            project = arg.split("=", 1)[1]
            i += 1
            continue
        rest.append(arg)
        i += 1
    if project is None and len(rest) >= 2 and rest[0] not in task_names and rest[1] in task_names \
            and not rest[0].startswith("-"):
        project, rest = rest[0], rest[1:]
    return project, rest


def main(argv: Sequence[str] | None = None) -> None:
    """Entry point of the ``robocore`` console script."""
    from invoke import Program

    from robocore.tasks import PROJECT_ENV, cli_namespace

    args = list(sys.argv[1:] if argv is None else argv)
    names = set(cli_namespace.task_names) | {n.replace("_", "-") for n in cli_namespace.task_names}
    project, rest = split_project(args, names)
    if project is not None:
        os.environ[PROJECT_ENV] = os.path.abspath(project)
    program = Program(namespace=cli_namespace, version=__version__, name="robocore", binary="robocore")
    program.run(["robocore", *rest])


if __name__ == "__main__":
    main()
