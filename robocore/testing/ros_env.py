"""ROS 2 inside the test process: which distro's wheels are installed, and the environment rclpy needs.

The test process joins the robot's graph with rclpy from the PyPI wheels (``robocore[testing]``).
They exist for CPython 3.11 and 3.12 on x86_64, for Jazzy and Kilted; a project of another
distro, or a machine without them, gets one line that says so instead of an import error.
"""

from __future__ import annotations

import os
import sys
from importlib import metadata
from pathlib import Path

from robocore.errors import RobocoreError

#: The wheel that marks each distro's rclpy in a Python environment.
DISTRO_WHEELS = {"jazzy": "ros-jazzy-rclpy", "kilted": "ros-kilted-rclpy"}
#: The rclpy versions each distro's wheels carry (the wrapper wheel may be missing when rclpy came alone).
RCLPY_MAJOR = {"jazzy": 7, "kilted": 9}


class TestEnvironmentError(RobocoreError):
    """The test process cannot join the robot's graph (no wheels, wrong distro)."""

    __test__ = False
    exit_code = 4


def installed_distro() -> str | None:
    """The ROS 2 distro whose rclpy wheels are installed in this Python, or None."""
    for distro, wheel in DISTRO_WHEELS.items():
        try:
            metadata.version(wheel)
        except metadata.PackageNotFoundError:
            continue
        return distro
    try:
        major = int(metadata.version("ros-rclpy").split(".")[0])
    except (metadata.PackageNotFoundError, ValueError):
        return None
    return next((d for d, m in RCLPY_MAJOR.items() if m == major), None)


def check_distro(wanted: str) -> None:
    """Raise TestEnvironmentError unless this Python has rclpy wheels of ``wanted``."""
    found = installed_distro()
    if found == wanted:
        return
    if wanted not in DISTRO_WHEELS:
        known = ", ".join(sorted(DISTRO_WHEELS))
        raise TestEnvironmentError(
            f"robot tests need rclpy for {wanted} in the test process, and {wanted} has no wheels on PyPI "
            f"(wheels exist for {known})")
    extra = "testing" if wanted == "jazzy" else f"testing-{wanted}"
    where = f"rclpy for {found}" if found else "no ROS 2 wheels"
    raise TestEnvironmentError(
        f"robot tests of a {wanted} project need rclpy for {wanted} in the test process, which has {where}: "
        f"pip install 'robocore[{extra}]' (CPython 3.11/3.12 on x86_64)")


def prepare(environment: dict[str, str]) -> None:
    """Set what rclpy reads (the robot's discovery settings, the wheels' prefix) before it is imported."""
    prefix = sys.prefix
    current = os.environ.get("AMENT_PREFIX_PATH", "")
    if prefix not in current.split(os.pathsep):
        os.environ["AMENT_PREFIX_PATH"] = os.pathsep.join(p for p in (prefix, current) if p)
    os.environ.update(environment)


def add_install_tree(install: Path) -> list[str]:
    """Make a project's built packages importable here when their Python matches; return what could not load.

    A colcon install tree holds ``<pkg>/lib/pythonX.Y/site-packages`` and the shared libraries of
    interface packages under ``<pkg>/lib``; the libraries are loaded up front because the
    dynamic loader reads ``LD_LIBRARY_PATH`` only when the process starts.
    """
    version = f"python{sys.version_info.major}.{sys.version_info.minor}"
    problems: list[str] = []
    if not install.is_dir():
        return problems
    libraries: list[Path] = []
    for package in sorted(p for p in install.iterdir() if p.is_dir()):
        lib = package / "lib"
        if not lib.is_dir():
            continue
        site = lib / version / "site-packages"
        others = [p.name for p in lib.glob("python3*") if p.name != version]
        if site.is_dir():
            if str(site) not in sys.path:
                sys.path.append(str(site))
            paths = os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)
            if str(package) not in paths:
                os.environ["AMENT_PREFIX_PATH"] = os.pathsep.join(p for p in (*paths, str(package)) if p)
        elif others:
            problems.append(f"{package.name}: built for {others[0]}, the test process is {version}: "
                            "use robot.exec to reach it from a component")
        libraries += sorted(lib.glob("*.so"))
    problems += _preload(libraries)
    return problems


def _preload(libraries: list[Path]) -> list[str]:
    """Load shared libraries globally, in passes, so that each finds the ones it needs already loaded."""
    import ctypes

    pending = list(libraries)
    errors: dict[Path, str] = {}
    while pending:
        failed = []
        for library in pending:
            try:
                ctypes.CDLL(str(library), mode=ctypes.RTLD_GLOBAL)
            except OSError as error:
                failed.append(library)
                errors[library] = str(error)
        if len(failed) == len(pending):
            break
        pending = failed
    return [f"{lib.parent.parent.name}: {lib.name} does not load here ({errors[lib]})" for lib in pending]
