"""colcon command lines and the reading of colcon's per-package progress (pure)."""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from robocore.errors import BuildError, UsageError
from robocore.plan import naming

CONTAINER_BUILD = "/robocore/build"
CONTAINER_LOG = "/robocore/log"
CONTAINER_CCACHE = "/robocore/ccache"

#: colcon event handlers: a line when a package starts and ends, no build output on the console (it is in
#: the log folder). Only handlers of colcon-core: naming one that is not installed is an error.
EVENT_HANDLERS = ("console_start_end+", "console_direct-")

_EVENT_RE = re.compile(r"^(?P<what>Starting|Finished|Failed|Aborted)\s+(?:>>>|<<<)\s+(?P<pkg>\S+)"
                       r"(?:\s+\[(?P<secs>[0-9.]+)s[],])?")


#: The environment of colcon's build and test containers: no install tree sourced by the entrypoint
#: (colcon sets up each package's environment itself), no bytecode written into the mounted sources.
CONTAINER_ENV = {"HOME": "/tmp", "ROBOCORE_NO_INSTALL": "1", "PYTHONDONTWRITEBYTECODE": "1"}


def build_env(cores: int, *, ccache: bool = False) -> dict[str, str]:
    """The environment of colcon's build container: :data:`CONTAINER_ENV`, CMake and make running
    ``cores`` jobs, and with ``ccache`` the compilers launched through ccache, whose cache is mounted at
    :data:`CONTAINER_CCACHE` (it outlives the build folder, so ``build --full`` and a new image reuse it)."""
    env = {**CONTAINER_ENV, "CMAKE_BUILD_PARALLEL_LEVEL": str(cores), "MAKEFLAGS": f"-j{cores}"}
    if ccache:
        # depend mode: a miss runs the compiler once, taking the included files from its -MD output (CMake asks
        # for it), where the default mode runs the preprocessor first: under qemu that is seconds per file
        env.update(CCACHE_DIR=CONTAINER_CCACHE, CCACHE_DEPEND="1", CMAKE_C_COMPILER_LAUNCHER="ccache",
                   CMAKE_CXX_COMPILER_LAUNCHER="ccache")
    return env


def workspace_mounts(workspace: Path, out: Path, ccache: Path | None = None) -> dict[str, str]:
    """``{host path: container path}`` of colcon's build and test containers: the component's workspace,
    its output folders ``out``/{build,install,log} and, for builds with ccache, the ``ccache`` folder."""
    mounts = {
        str(workspace): naming.CONTAINER_WS,
        str(out / "build"): CONTAINER_BUILD,
        str(out / "install"): naming.CONTAINER_INSTALL,
        str(out / "log"): CONTAINER_LOG,
    }
    if ccache is not None:
        mounts[str(ccache)] = CONTAINER_CCACHE
    return mounts


def workspace_build_argv(packages_above: Sequence[str] = (), workers: int | None = None) -> list[str]:
    """``colcon build`` of the workspace mounted at :data:`naming.CONTAINER_WS`.

    Install tree at :data:`naming.CONTAINER_INSTALL` (the same absolute path at run time),
    build and log folders beside it. ``packages_above``: rebuild only those packages and
    the packages that depend on them; ``workers``: packages built at once (colcon's default
    otherwise).
    """
    argv = [
        "colcon", "--log-base", CONTAINER_LOG, "build",
        "--base-paths", naming.CONTAINER_WS,
        "--build-base", CONTAINER_BUILD,
        "--install-base", naming.CONTAINER_INSTALL,
    ]
    if workers:
        argv += ["--parallel-workers", str(workers)]
    if packages_above:
        argv += ["--packages-above", *packages_above]
    return [*argv, "--event-handlers", *EVENT_HANDLERS]


def workspace_test_argv(packages: Sequence[str] = ()) -> list[str]:
    """``colcon test`` of the workspace that :func:`workspace_build_argv` built, with the same folders.

    Results stay where colcon puts them, under each package's build folder (``pytest.xml`` of
    ``ament_python`` packages, ``test_results/`` of ``ament_cmake`` ones). colcon's exit code says
    whether the tests could run, not whether they passed (no ``--return-code-on-test-failure``):
    the results say that. ``packages``: test only these (``--packages-select``); all when empty.
    """
    argv = [
        "colcon", "--log-base", CONTAINER_LOG, "test",
        "--base-paths", naming.CONTAINER_WS,
        "--build-base", CONTAINER_BUILD,
        "--install-base", naming.CONTAINER_INSTALL,
    ]
    if packages:
        odd = [p for p in packages if not _PACKAGE_RE.match(p)]
        if odd:
            raise UsageError(f"not a package name: {odd[0]!r}")
        argv += ["--packages-select", *packages]
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


def unbuilt(packages: Iterable[str], changed: Sequence[str] | None, events: Iterable[PackageEvent]) -> list[str]:
    """The packages a build asked for (``changed``, or every package when None) that colcon never finished.

    colcon exits 0 having built nothing when it cannot load the task extension of a package's build type (an
    image whose colcon lacks colcon-ros, say: it only warns); a build that trusted the exit code would record
    and report packages that have no install tree."""
    finished = {e.package for e in events if e.state == "finished"}
    wanted = list(packages) if changed is None else list(changed)
    return sorted(p for p in wanted if p not in finished)


def refuse_unbuilt(component: str, packages: Iterable[str], changed: Sequence[str] | None,
                   events: Iterable[PackageEvent], output: Sequence[str], *, where: str = "") -> None:
    """BuildError when colcon exited 0 without finishing a package it was asked for (:func:`unbuilt`), with the
    last lines of colcon's other output (its warning says why); ``where``: `` on host NAME`` for a host build."""
    missing = unbuilt(packages, changed, events)
    if missing:
        tail = "\n".join(f"  {line}" for line in output[-20:])
        raise BuildError(f"component {component}: colcon build{where} exited 0 without building "
                         f"{', '.join(missing)}\n{tail}",
                         hint="colcon skips a package whose build type it has no extension for: does the "
                              "component's image have colcon-ros (python3-colcon-ros)?")


def parse_event(line: str) -> PackageEvent | None:
    """The package event on a colcon console line, if any."""
    match = _EVENT_RE.match(line.strip())
    if not match:
        return None
    state = {"Starting": "started", "Finished": "finished", "Failed": "failed", "Aborted": "aborted"}[match["what"]]
    secs = float(match["secs"]) if match["secs"] else None
    return PackageEvent(package=match["pkg"], state=state, seconds=secs)


_NAME_RE = re.compile(r"<name>\s*([A-Za-z0-9_\-]+)\s*</name>")
#: A package name that can stand on a colcon command line (never an option).
_PACKAGE_RE = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_\-]*$")


def package_name(package_xml: str) -> str | None:
    """The ``<name>`` of a package.xml text."""
    match = _NAME_RE.search(package_xml)
    return match.group(1) if match else None
