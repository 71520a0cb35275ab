"""prepare-base, stage and build (issue #3)."""

from __future__ import annotations

from robocore.commands.context import Options
from robocore.errors import NotImplementedYet


def prepare_base(options: Options, *, force: bool) -> None:
    """Build the base image when its inputs changed."""
    options.load()
    raise NotImplementedYet("prepare-base is not implemented yet")


def stage(options: Options, *, refresh: bool, component: str | None, force: bool) -> None:
    """Build component images and write compose files."""
    options.load()
    raise NotImplementedYet("stage is not implemented yet")


def build(options: Options, *, component: str | None) -> None:
    """colcon-build component workspaces inside their staged images."""
    options.load()
    raise NotImplementedYet("build is not implemented yet")
