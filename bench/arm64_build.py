"""The talker's C++ build for arm64 (emulated through qemu on an amd64 machine) beside amd64, in one run.

Two copies of the template's noetic project on the debian base (``robocore init --distro noetic --base debian``):
in one the talker runs on this machine (amd64), in the other on an arm64 host (``jetson``, never contacted:
``build`` runs on this machine, in an emulated container). For each arch, ``robocore build --component talker``:

1. clean, ccache cold: the talker's build and install trees and its arch's ccache folder removed;
2. clean, ccache warm: the build and install trees removed (ccache outlives them);
3. one-line edit of the roscpp talker's ``talker.cpp`` (incremental);
4. no change (nothing to do).

Printed as one table: seconds and C++ objects compiled per arch, and the arm64/amd64 ratio. ``prepare-base`` and
``stage`` of each copy are timed too (the arm64 ones include bootstrapping the arm64 Debian root when it is not
on this machine yet: run with no ``robocore/arm64/debian:bookworm-debian`` image for "the arm64 base from
nothing"). Goals: one-line edit < 30 s emulated; no change < 1 s; the arm64 base from nothing < 10 min.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

import yaml
from harness import Figure, record, robocore

ARCHES = ("amd64", "arm64")
#: Goals of the arm64 (emulated) figures, by step.
GOALS = {"one-line edit of talker.cpp": 30.0, "no change": 1.0}


def compiled_objects(project: Path, since: float) -> int:
    """``Building CXX object`` lines of the talker package's colcon log, if colcon ran after ``since``."""
    log = project / ".robocore" / "build" / "talker" / "log" / "latest_build" / "demo_talker" / "stdout_stderr.log"
    if not log.is_file() or log.stat().st_mtime < since:
        return 0
    return log.read_text(errors="replace").count("Building CXX object")


def timed(project: Path, *args: str) -> tuple[float, int]:
    wall, started = time.time(), time.perf_counter()
    robocore(project, *args)
    return time.perf_counter() - started, compiled_objects(project, wall)


def lan_address() -> str:
    """This machine's first non-loopback IPv4 address (the address a robot's other hosts would reach it at)."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.connect(("192.0.2.1", 9))  # no packet is sent: this only picks the outgoing interface
        return str(probe.getsockname()[0])


def make_project(parent: Path, arch: str) -> Path:
    """A noetic project whose talker runs on a host of ``arch`` (the ROS master stays on this machine)."""
    project = parent / f"bench-{arch}"
    robocore(None, "init", str(project), "--defaults", "--distro", "noetic", "--base", "debian")
    if arch != "amd64":
        data = yaml.safe_load((project / "robot.yaml").read_text())
        # ROS 1 nodes on two hosts need a reachable master: this machine's LAN address, not the template's loopback
        data["hosts"][0]["ip"] = lan_address()
        data["hosts"].append({"name": "jetson", "ip": "192.0.2.10", "user": "robot", "arch": arch})
        for comp in data["components"]:
            if comp["name"] == "talker":
                comp["runs_on"] = "jetson"
        (project / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    return project


def build_rows(project: Path, arch: str) -> dict[str, tuple[float, int]]:
    out = project / ".robocore" / "build" / "talker"
    code = next(p for p in (project / "components" / "talker").rglob("talker.cpp"))

    def clean() -> None:
        for tree in ("build", "install"):
            shutil.rmtree(out / tree, ignore_errors=True)

    rows = {}
    clean()
    shutil.rmtree(project / ".robocore" / "ccache" / arch, ignore_errors=True)
    rows["clean, ccache cold"] = timed(project, "build", "--component", "talker")
    clean()
    rows["clean, ccache warm"] = timed(project, "build", "--component", "talker")
    original = code.read_text()
    try:
        code.write_text(original.replace("rate(2.0)", "rate(2.5)", 1))
        rows["one-line edit of talker.cpp"] = timed(project, "build", "--component", "talker")
    finally:
        code.write_text(original)
    robocore(project, "build", "--component", "talker")  # back to the original source
    rows["no change"] = timed(project, "build", "--component", "talker")
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.parse_args()
    parent = Path(tempfile.mkdtemp(prefix="robocore-bench-arm64-"))
    try:
        table: dict[str, dict[str, tuple[float, int]]] = {}
        for arch in ARCHES:
            project = make_project(parent, arch)
            table.setdefault("prepare-base", {})[arch] = timed(project, "prepare-base")
            table.setdefault("stage", {})[arch] = timed(project, "stage")
            robocore(project, "build")
            for label, row in build_rows(project, arch).items():
                table.setdefault(label, {})[arch] = row
        print("talker build, amd64 native beside arm64 emulated (qemu-user); seconds (C++ objects compiled)")
        print(f"{'step':30} {'amd64':>14} {'arm64':>14} {'arm64/amd64':>12}")
        for label, cells in table.items():
            amd_s, amd_o = cells["amd64"]
            arm_s, arm_o = cells["arm64"]
            ratio = arm_s / amd_s if amd_s > 0 else float("nan")
            print(f"{label:30} {amd_s:8.1f} ({amd_o:2d}) {arm_s:8.1f} ({arm_o:2d}) {ratio:12.1f}")
        figures = []
        for label, cells in table.items():
            (amd_s, amd_o), (arm_s, arm_o) = cells["amd64"], cells["arm64"]
            limit = GOALS.get(label)
            figures.append(Figure(f"{label}, amd64", amd_s, "s", detail=f"{amd_o} C++ objects"))
            figures.append(Figure(f"{label}, arm64 (emulated)", arm_s, "s", f"< {limit:g} s" if limit else None,
                                  arm_s / amd_s if amd_s > 0 else None, "arm64 / amd64",
                                  arm_s < limit if limit else None, f"{arm_o} C++ objects"))
        record("arm64_build", figures, goals=["one-line edit < 30 s emulated", "no change < 1 s",
                                              "the arm64 base from nothing < 10 min (prepare-base, arm64, when no "
                                              "arm64 base image was on the machine)"])
    finally:
        shutil.rmtree(parent, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
