"""CI sessions: lint, typecheck, tests (no Docker), integration (Docker required).

``scripts/test`` is the one way in: it makes the project's .venv, starts the arm64 suites' images in the
background, and runs these four sessions with ``--no-venv`` in that venv; CI runs it (``.ci/run``), and
``invoke test`` in this repository runs it too. Plain ``nox`` runs the same sessions, each in a virtualenv of its
own, with the images started by the integration session instead (a later start, the same results).
"""

from __future__ import annotations

import os

import nox

#: Seconds a session's pytest may take, after Ctrl-C or .ci/run's time limit, to tear its fixtures down and
#: print its summary (nox's default of 0.3 s would cut the summary off).
INTERRUPT_GRACE = 150.0

#: Lanes of the integration session (pytest-xdist workers, one per core of CI's machine): ``ROBOCORE_IT_LANES`` sets
#: another number, 0 none (the session in one process, as before lanes).
LANES = 2

nox.options.sessions = ["lint", "typecheck", "tests", "integration"]
nox.options.reuse_existing_virtualenvs = True


def _install(session: nox.Session) -> None:
    if not isinstance(session.virtualenv, nox.virtualenv.PassthroughEnv):
        session.install("-e", ".[dev]")


@nox.session
def lint(session: nox.Session) -> None:
    _install(session)
    session.run("ruff", "check", "robocore", "tests", "integration", "bench", "noxfile.py", "tasks.py")


@nox.session
def typecheck(session: nox.Session) -> None:
    _install(session)
    session.run("mypy", "robocore")


@nox.session
def tests(session: nox.Session) -> None:
    _install(session)
    # on both cores (pytest-xdist), the arm64 images being made in the background meanwhile
    session.run("pytest", "tests", "-n", "2", *session.posargs, interrupt_timeout=INTERRUPT_GRACE)


@nox.session
def integration(session: nox.Session) -> None:
    """Docker suites. Fails loudly when there is no Docker daemon: never skips."""
    _install(session)
    session.env["TESTCONTAINERS_RYUK_DISABLED"] = "true"
    # a test that hangs fails after 25 minutes (its fixtures' image builds included) instead of stalling CI;
    # the 60 slowest tests are printed on every run (and on an interrupted one), so time growth is seen early;
    # the modules run in lanes, xdist workers taking whole groups in integration/lanes.py's order, and the table of
    # where the minutes went ends the output (integration/ci_times.py)
    lanes = os.environ.get("ROBOCORE_IT_LANES", str(LANES))
    session.run("pytest", "integration", "-p", "no:cacheprovider", "--timeout=1500", "--durations=60", "-v",
                "-n", lanes, "--dist", "loadgroup", "--no-loadscope-reorder",
                *session.posargs, interrupt_timeout=INTERRUPT_GRACE)
