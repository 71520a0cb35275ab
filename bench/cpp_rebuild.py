"""C++ rebuilds of a ROS 1 project: a one-line edit beside full rebuilds, in one run.

On the template's noetic project on the debian base (``robocore init --distro noetic --base debian``,
built once first), ``robocore build --component talker``:

1. clean, ccache cold: the talker's build and install trees and the ccache folder removed, ``build``;
2. clean, ccache warm: the build and install trees removed, ``build`` (ccache outlives them);
3. one-line edit of the roscpp talker's ``talker.cpp``: ``build`` (incremental);
4. no change: ``build`` (nothing to do).

For each: seconds, and how many C++ objects CMake compiled (``Building CXX object`` lines of the
package's colcon log). Goal: the one-line edit compiles one object, several times faster than a clean
rebuild.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

from harness import Figure, record, robocore


def compiled_objects(project: Path, since: float) -> int:
    """``Building CXX object`` lines of the talker package's colcon log, if colcon ran after ``since``."""
    log = project / ".robocore" / "build" / "talker" / "log" / "latest_build" / "demo_talker" / "stdout_stderr.log"
    if not log.is_file() or log.stat().st_mtime < since:
        return 0  # colcon did not run
    return log.read_text(errors="replace").count("Building CXX object")


def timed_build(project: Path, *flags: str) -> tuple[float, int]:
    wall, started = time.time(), time.perf_counter()
    robocore(project, "build", "--component", "talker", *flags)
    return time.perf_counter() - started, compiled_objects(project, wall)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--project", type=Path, help="a noetic project made from the template (default: a new one)")
    args = parser.parse_args()
    parent = None
    if args.project is None:
        parent = Path(tempfile.mkdtemp(prefix="robocore-bench-"))
        project = parent / "bench-noetic"
        robocore(None, "init", str(project), "--defaults", "--distro", "noetic", "--base", "debian")
    else:
        project = args.project
    try:
        for step in ("prepare-base", "stage", "build"):
            robocore(project, step)
        out = project / ".robocore" / "build" / "talker"
        code = next(p for p in (project / "components" / "talker").rglob("talker.cpp"))
        rows = []

        def clean() -> None:  # no build or install tree: the next build is a first build
            for tree in ("build", "install"):
                shutil.rmtree(out / tree, ignore_errors=True)

        clean()
        shutil.rmtree(project / ".robocore" / "ccache", ignore_errors=True)
        rows.append(("clean, ccache cold", *timed_build(project)))
        clean()
        rows.append(("clean, ccache warm", *timed_build(project)))
        original = code.read_text()
        try:
            code.write_text(original.replace("rate(2.0)", "rate(2.5)", 1))
            rows.append(("one-line edit of talker.cpp (build)", *timed_build(project)))
        finally:
            code.write_text(original)
        robocore(project, "build", "--component", "talker")  # back to the original source
        rows.append(("no change (build)", *timed_build(project)))
        edit = rows[2][1]
        print(f"{'talker build':40} {'seconds':>8} {'objects':>8} {'x edit':>7}")
        for label, seconds, objects in rows:
            print(f"{label:40} {seconds:8.1f} {objects:8d} {seconds / edit:7.1f}")
        edit_objects = rows[2][2]
        record("cpp_rebuild", [
            Figure(label, seconds, "s", "1 object, faster than a clean rebuild" if label.startswith("one-line")
                   else None, seconds / edit, "x the edit", edit_objects == 1 and edit < rows[1][1]
                   if label.startswith("one-line") else None, f"{objects} C++ objects compiled")
            for label, seconds, objects in rows],
            goals=["the one-line edit compiles one object, several times faster than a clean rebuild"],
            notes=["the template's noetic project on the debian base; `robocore build --component talker`"])
    finally:
        if parent is not None:
            shutil.rmtree(parent, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
