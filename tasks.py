"""Developer tasks of the robocore repository itself: ``invoke demo``, ``invoke test``, ``invoke bench``."""

from invoke import Context, task


@task
def demo(c: Context) -> None:
    """The demo robot on this machine (same as scripts/demo)."""
    c.run("python -m robocore.demo", pty=False)


@task
def test(c: Context) -> None:
    """Every nox session (same as scripts/test)."""
    c.run("nox --no-venv -s lint typecheck tests integration")


@task
def bench(c: Context) -> None:
    """Every benchmark in bench/."""
    c.run("python bench/run_all.py")
