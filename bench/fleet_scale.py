"""Fleet files at scale without Docker: 10,000 robots validated, rolled out (dry run) and exported; huge records.

A fleet of 10,000 robots is fleet.yaml's documented maximum; export records of 100,000 and 1,000,000 names show
that what robocore reads stays bounded.

One model (robot.yaml: one host, one component with an image) and fleet.yaml of N robots; each step runs robocore as
a user would (a new process, start-up included) and prints its wall-clock and CPU seconds (the machine is shared:
the CPU figure is what the step costs) and the ratio of its CPU time to its goal:

1. ``validate`` (the no-op memo dropped first, so the file is read);
2. ``fleet rollout v1 --dry-run`` (engine swarm, a release record of v1);
3. ``export kubernetes`` of the same robots (engine kubernetes) into a new folder, then again into the same folder
   (every file unchanged, compared);
4. ``export kubernetes`` of one robot into a folder whose ``.robocore-written`` lists 100,000 names it never wrote,
   then 1,000,000 (over its 16 MB bound: refused in one line).

Goals: validate < 2 s; dry-run rollout and export < 5 s; a record of any size read in < 2 s.

``--baseline DIR`` (a folder holding another robocore package, e.g. ``git archive main robocore | tar -x -C DIR``)
runs each step with that robocore too, just before this one, on the same files, and prints its CPU seconds and
the ratio beside: a before-and-after in one run, under the same load (the figures recorded are this tree's).

    python bench/fleet_scale.py [--robots N] [--baseline DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

from harness import Figure, record, robocore_command

DIGEST = "sha256:" + "ab" * 32
ROBOT_YAML = """\
ros_distro: jazzy
image_prefix: bot-
registry: 10.0.0.2:5000
hosts:
  - {name: main, ip: 192.168.1.10}
components:
  - {name: talker, image: "ros:jazzy", runs_on: main}
"""


def fleet_yaml(robots: int, engine: str) -> str:
    head = "manager: {ip: 10.0.0.2}\n" if engine == "swarm" else "engine: kubernetes\n"
    return head + "robots:\n" + "".join(
        f"  - {{name: r{i}, hosts: {{main: {{ip: 10.{i // 65536 % 256 + 1}.{i // 256 % 256}.{i % 256}}}}}}}\n"
        for i in range(robots))


def project(root: Path, robots: int, engine: str) -> Path:
    root.mkdir(parents=True)
    (root / "robot.yaml").write_text(ROBOT_YAML)
    (root / "fleet.yaml").write_text(fleet_yaml(robots, engine))
    releases = root / ".robocore" / "releases"
    releases.mkdir(parents=True, mode=0o700)
    path = releases / "v1.json"
    path.write_text(json.dumps({"format": 1, "version": "v1", "registry": "10.0.0.2:5000",
                                "components": {"talker": {"amd64": f"10.0.0.2:5000/bot-talker@{DIGEST}"}},
                                "base": {"amd64": f"10.0.0.2:5000/bot-base@{DIGEST}"}}))
    path.chmod(0o600)
    return root


def timed(root: Path, *args: str, robocore: Path | None = None) -> tuple[float, float, int, str]:
    """Wall-clock and CPU seconds of ``robocore -p ROOT ARGS``, its exit code and its last line; ``robocore``: the
    folder of another robocore package to run instead (first on ``PYTHONPATH``)."""
    if args[0] == "validate":  # the no-op memo dropped, so that the file is read
        shutil.rmtree(root / ".robocore" / "noop", ignore_errors=True)
    env = None if robocore is None else {**os.environ, "PYTHONPATH": str(robocore)}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    done = subprocess.run([*robocore_command(), "-p", str(root), *args], capture_output=True, text=True,
                          check=False, timeout=1800, cwd=root, env=env)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
    lines = (done.stdout + done.stderr).strip().splitlines()
    if "Traceback" in done.stderr:
        raise SystemExit(done.stderr[-3000:])
    return wall, cpu, done.returncode, lines[-1][:140] if lines else ""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", type=int, default=10_000, help="robots of the fleet (default 10,000)")
    parser.add_argument("--baseline", type=Path, help="a folder holding another robocore package, run beside")
    args = parser.parse_args()
    baseline = args.baseline.resolve() if args.baseline else None
    if baseline is not None and not (baseline / "robocore" / "__init__.py").is_file():
        raise SystemExit(f"--baseline {baseline}: no robocore package in it")
    parent = Path(tempfile.mkdtemp(prefix="robocore-bench-fleet-scale-"))
    rows: list[tuple[str, float, float, float, int, str, float | None]] = []

    def step(label: str, goal: float, root: Path, *command: str, baseline_command: tuple[str, ...] = ()) -> None:
        """One row: the baseline's run first (when given), then this tree's."""
        before = timed(root, *(baseline_command or command), robocore=baseline)[1] if baseline else None
        rows.append((label, goal, *timed(root, *command), before))

    try:
        swarm = project(parent / "swarm", args.robots, "swarm")
        step(f"validate, {args.robots:,} robots", 2.0, swarm, "validate")
        step(f"fleet rollout --dry-run, {args.robots:,} robots", 5.0, swarm, "fleet", "rollout", "v1", "--dry-run")
        k8s = project(parent / "k8s", args.robots, "kubernetes")
        export, old = ("export", "kubernetes", "out", "--tag", "v1"), ("export", "kubernetes", "old", "--tag", "v1")
        for label in ("new folder", "unchanged"):
            step(f"export kubernetes, {args.robots:,} robots, {label}", 5.0, k8s, *export, baseline_command=old)
        if baseline is not None:
            differ = subprocess.run(["diff", "-rq", "out", "old"], cwd=k8s, capture_output=True, text=True)
            if differ.returncode != 0:
                raise SystemExit(f"the exports differ from the baseline's:\n{differ.stdout[:3000]}")
            print(f"export kubernetes: {sum(1 for p in (k8s / 'out').rglob('*') if p.is_file()):,} files, "
                  "byte-identical to the baseline's")
        one = project(parent / "one", 1, "kubernetes")
        for names in (100_000, 1_000_000):
            for out in (one / f"out-{names}", one / f"old-{names}"):
                out.mkdir()
                record_file = out / ".robocore-written"
                record_file.write_text("".join(f"robots/old-{i}/namespace.yaml\n" for i in range(names)))
                record_file.chmod(0o600)
            size = (one / f"out-{names}" / ".robocore-written").stat().st_size
            step(f"export, a record of {names:,} names ({size / 1e6:.0f} MB)", 2.0, one,
                 "export", "kubernetes", f"out-{names}", "--tag", "v1",
                 baseline_command=("export", "kubernetes", f"old-{names}", "--tag", "v1"))
    finally:
        shutil.rmtree(parent, ignore_errors=True)
    width = max(len(row[0]) for row in rows)
    side = f"  {'baseline CPU s':>14}  {'baseline/CPU':>12}" if baseline else ""
    print(f"{'step':<{width}}  {'wall s':>7}  {'CPU s':>6}  {'goal':>5}  {'goal/CPU':>8}{side}  exit  last line")
    figures = []
    for label, goal, wall, cpu, code, last, before in rows:
        beside = f"  {before:>14.2f}  {before / cpu:>11.2f}x" if before is not None else ""
        print(f"{label:<{width}}  {wall:>7.2f}  {cpu:>6.2f}  {goal:>5.1f}  {goal / cpu:>7.2f}x{beside}  {code:>4}  "
              f"{last}")
        detail = f"{wall:.2f} s wall-clock, exit {code}" + (f"; baseline {before:.2f} s CPU" if before else "")
        figures.append(Figure(label, cpu, "s CPU", f"< {goal:g} s", goal / cpu, "goal / CPU time", cpu < goal, detail))
    load = os.getloadavg()[0]
    notes = [f"load average {load:.1f} on {os.cpu_count()} cores at the end: wall-clock figures are inflated; "
             "the CPU time (process and children, start-up included) is the cost"]
    if baseline is not None:
        notes.append("baseline: each step also run just before with the robocore of --baseline (the commit before "
                     "the speed-ups), its CPU seconds in each row's detail")
    record("fleet_scale", figures, goals=["10,000 robots: validate < 2 s, dry-run rollout and export < 5 s",
                                          "a .robocore-written of any size read in < 2 s (bounded: 16 MB)"],
           notes=notes)


if __name__ == "__main__":
    main()
