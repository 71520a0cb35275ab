"""The no-op memo seconds after an edit ("racily clean" files are hashed, not a reason to skip the memo).

A project made by ``robocore init --defaults`` (no image needed) answers ``validate`` side by side:
- bare ``python -c pass`` (the floor);
- the ordinary path (``ROBOCORE_NO_MEMO=1``);
- the memo with every file older than the memo's racy window (``noop.RACY_SECONDS``);
- the memo right after ``robot.yaml`` was saved again (same content, new times): one ordinary run records the
  memo with the young file's hash, and the next run replays it (hashing the file again). Each such row says how
  old robot.yaml was when the recording run started (inside the window: its hash is in the memo).

Before this change no memo was recorded by a run that started within 2 s of a save: the next run took the
ordinary path again, and so on until a run started with every file older than the window. The goal is a
replay under 0.1 s at any file age; on a loaded machine compare the memo rows with bare start-up (same run), and
the CPU time of each (the child's user + system time), which the load inflates less.

    python bench/noop_young.py [--runs N]
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from harness import Figure, record

from robocore.commands.support import noop

GOAL_S = 0.1


def run(argv: list[str], cwd: Path, **env: str) -> tuple[float, float]:
    """(wall-clock seconds, CPU seconds) of one run."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(argv, cwd=cwd, env={**os.environ, **env}, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        sys.exit(f"{argv} failed: {done.stderr}")
    return seconds, after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime


def medians(runs: list[tuple[float, float]]) -> tuple[float, float]:
    return statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs)


def row(label: str, figure: tuple[float, float], bare: float, mark: str = "") -> None:
    seconds, cpu = figure
    print(f"{label:44} {seconds:6.3f} s  {seconds / bare:5.2f}x bare  {seconds / GOAL_S:5.2f}x goal  "
          f"CPU {cpu:6.3f} s  {cpu / GOAL_S:5.2f}x goal{mark}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=7)
    args = parser.parse_args()
    py = sys.executable
    # robocore's byte code is written by the first run, as for any user (set, every run would compile the sources
    # changed since the byte code was last written)
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
    validate = [py, "-m", "robocore", "validate"]
    with tempfile.TemporaryDirectory(prefix="robocore-bench-young-") as tmp:
        subprocess.run([py, "-m", "robocore", "init", "robot", "--defaults"], cwd=tmp, check=True, capture_output=True)
        root = Path(tmp) / "robot"
        robot = root / "robot.yaml"
        text = robot.read_bytes()
        bare_row = medians([run([py, "-c", "pass"], root) for _ in range(args.runs)])
        ordinary_row = medians([run(validate, root, ROBOCORE_NO_MEMO="1") for _ in range(args.runs)])
        time.sleep(noop.RACY_SECONDS + 0.5)
        run(validate, root)  # records the memo of old files
        old_row = medians([run(validate, root) for _ in range(args.runs)])
        young: list[tuple[tuple[float, float], float]] = []
        for _ in range(args.runs):
            robot.write_bytes(text)  # saved again: new times, same content
            age = time.time() - robot.stat().st_mtime  # its age when the recording run starts
            run(validate, root)  # the ordinary path finds nothing to do and records (the young file hashed)
            young.append((run(validate, root), age))
        print(f"validate on {root} (median of {args.runs}; load average {os.getloadavg()[0]:.1f} on "
              f"{os.cpu_count()} cores: compare rows of this run)")
        bare, ordinary, old = bare_row[0], ordinary_row[0], old_row[0]
        row("python -c pass", bare_row, bare)
        row("ordinary path (ROBOCORE_NO_MEMO=1)", ordinary_row, bare)
        row("memo, files older than the racy window", old_row, bare)
        inside = [figure for figure, age in young if age < noop.RACY_SECONDS]
        for figure, age in young:
            row(f"memo recorded {age:.2f} s after a save", figure, bare,
                "" if age < noop.RACY_SECONDS else "  (outside the window)")
        if inside:
            row("memo, young files (median of those inside)", medians(inside), bare)
    young_median, young_cpu = medians(inside) if inside else (None, None)
    record("noop_young", [
        Figure("python -c pass", bare, "s"),
        Figure("ordinary path (ROBOCORE_NO_MEMO=1)", ordinary, "s", ratio=ordinary / bare, ratio_of="x bare python"),
        Figure("memo, files older than the racy window", old, "s", "< 0.1 s", old / bare, "x bare python",
               old < 0.1),
        Figure("memo, young files (median of those inside the window)", young_median, "s", "< 0.1 s",
               young_median / bare if young_median else None, "x bare python",
               young_median < 0.1 if young_median else None,
               f"{len(inside)} of {len(young)} recorded inside the {noop.RACY_SECONDS:g} s window"),
        Figure("memo, files older than the racy window: CPU time", old_row[1], "s", "< 0.1 s",
               old_row[1] / GOAL_S, "of the goal", old_row[1] < GOAL_S, "user + system, less inflated by the load"),
        Figure("memo, young files: CPU time", young_cpu, "s", "< 0.1 s", young_cpu / GOAL_S if young_cpu else None,
               "of the goal", young_cpu < GOAL_S if young_cpu else None, "user + system, less inflated by the load"),
    ], goals=["a memo replay under 0.1 s at any file age (on a loaded machine: compare with bare start-up)"],
        notes=[f"validate; median of {args.runs} runs each"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
