"""CI sessions: lint, typecheck, tests (no Docker), integration (Docker required).

``scripts/test`` runs them with ``--no-venv`` inside the project's .venv; plain ``nox``
makes a virtualenv per session instead.
"""

from __future__ import annotations

import nox

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
    session.run("pytest", "tests", *session.posargs)


@nox.session
def integration(session: nox.Session) -> None:
    """Docker suites. Fails loudly when there is no Docker daemon: never skips."""
    _install(session)
    session.env["TESTCONTAINERS_RYUK_DISABLED"] = "true"
    # a test that hangs fails after 25 minutes (its fixtures' image builds included) instead of stalling CI
    session.run("pytest", "integration", "-p", "no:cacheprovider", "--timeout=1500", *session.posargs)
