"""Developer tasks of the robocore repository itself: ``invoke demo``, ``invoke test``, ``invoke bench``.

``demo`` and ``test`` are aliases of the two scripts the README names (``scripts/demo``, ``scripts/test``), so
that there is one way into each: ``scripts/test`` is also what CI runs (``.ci/run``).
"""

import shlex
from pathlib import Path

from invoke import Context, task

ROOT = Path(__file__).resolve().parent


@task
def demo(c: Context) -> None:
    """The demo robot on this machine: runs scripts/demo."""
    c.run(shlex.quote(str(ROOT / "scripts" / "demo")), pty=False)


@task
def test(c: Context) -> None:
    """The full suite, as CI runs it: runs scripts/test."""
    c.run(shlex.quote(str(ROOT / "scripts" / "test")))


@task
def bench(c: Context) -> None:
    """Every benchmark in bench/."""
    c.run(f"python {shlex.quote(str(ROOT / 'bench' / 'run_all.py'))}")
