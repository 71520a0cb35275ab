"""colcon command lines and the reading of colcon's per-package progress (pure)."""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

from robocore.plan import naming

CONTAINER_BUILD = "/robocore/build"
CONTAINER_LOG = "/robocore/log"

#: colcon event handlers: a line when a package starts and ends, no build output on the console (it is in
#: the log folder). Only handlers of colcon-core: naming one that is not installed is an error.
EVENT_HANDLERS = ("console_start_end+", "console_direct-")

_EVENT_RE = re.compile(r"^(?P<what>Starting|Finished|Failed|Aborted)\s+(?:>>>|<<<)\s+(?P<pkg>\S+)"
                       r"(?:\s+\[(?P<secs>[0-9.]+)s[],])?")


def workspace_build_argv(packages_above: Sequence[str] = ()) -> list[str]:
    """``colcon build`` of the workspace mounted at :data:`naming.CONTAINER_WS`.

    Install tree at :data:`naming.CONTAINER_INSTALL` (the same absolute path at run time),
    build and log folders beside it. ``packages_above``: rebuild only those packages and
    the packages that depend on them.
    """
    argv = [
        "colcon", "--log-base", CONTAINER_LOG, "build",
        "--base-paths", naming.CONTAINER_WS,
        "--build-base", CONTAINER_BUILD,
        "--install-base", naming.CONTAINER_INSTALL,
    ]
    if packages_above:
        argv += ["--packages-above", *packages_above]
    return [*argv, "--event-handlers", *EVENT_HANDLERS]


def underlay_build_argv(source: str, install: str, build: str) -> list[str]:
    """``colcon build`` of dependencies baked into an image (merged install, no logs)."""
    return [
        "colcon", "--log-base", "/dev/null", "build", "--merge-install",
        "--base-paths", source, "--build-base", build, "--install-base", install,
        "--event-handlers", "console_start_end+", "console_direct+",
    ]


@dataclass(frozen=True)
class PackageEvent:
    """A package started, finished, failed or was aborted."""

    package: str
    state: str  # started | finished | failed | aborted
    seconds: float | None = None


def parse_event(line: str) -> PackageEvent | None:
    """The package event on a colcon console line, if any."""
    match = _EVENT_RE.match(line.strip())
    if not match:
        return None
    state = {"Starting": "started", "Finished": "finished", "Failed": "failed", "Aborted": "aborted"}[match["what"]]
    secs = float(match["secs"]) if match["secs"] else None
    return PackageEvent(package=match["pkg"], state=state, seconds=secs)


_NAME_RE = re.compile(r"<name>\s*([A-Za-z0-9_\-]+)\s*</name>")


def package_name(package_xml: str) -> str | None:
    """The ``<name>`` of a package.xml text."""
    match = _NAME_RE.search(package_xml)
    return match.group(1) if match else None
