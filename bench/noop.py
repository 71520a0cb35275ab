"""Benchmark of no-op tasks on an unchanged project, side by side with bare Python's start-up.

Prints, in one run, the median of N runs of each (goal < 0.3 s for validate, stage, build and status; on a
loaded machine, where bare start-up itself is slow, the same goal as a ratio: <= 1.8x bare start-up):
- bare ``python -c pass`` (the floor) and ``python -c "import robocore.cli"``;
- each task by its ordinary path (``ROBOCORE_NO_MEMO=1``: configuration loaded, images asked for,
  sources hashed) and by the no-op memo (``.robocore/noop``: one stat pass, one raw Docker API call);
  ``status`` asks the daemon for the live containers every time, its memo holds only robot.yaml's plan
  (:mod:`robocore.commands.support.status_memo`: the project's hosts must all be this machine).

Usage: python bench/noop.py [PROJECT] [--runs N]
PROJECT is a project after prepare-base, stage and build (default: a new template project in a temporary
folder, made ready first, which takes minutes on a machine without the base image).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from harness import Figure, record

GOAL = 0.3
#: The goal as a ratio to bare start-up, for a loaded machine: on a clean machine the ordinary
#: no-op stage took 0.50 s, three times bare Python's start-up, so 0.3 s is 1.8 times it.
GOAL_RATIO = 1.8
TASKS = ("validate", "stage", "build", "status")


def timed(argv: list[str], cwd: Path, env: dict[str, str]) -> float:
    start = time.perf_counter()
    done = subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True)
    elapsed = time.perf_counter() - start
    if done.returncode != 0:
        sys.exit(f"{' '.join(argv)} failed ({done.returncode}):\n{done.stdout}\n{done.stderr}")
    return elapsed


def median(argv: list[str], cwd: Path, runs: int, **env: str) -> float:
    environ = {**os.environ, **env}
    timed(argv, cwd, environ)  # warm: the memo written, the page cache filled
    return statistics.median(timed(argv, cwd, environ) for _ in range(runs))


def ready_project(folder: Path) -> Path:
    robocore = [sys.executable, "-m", "robocore"]
    project = folder / "robot"
    subprocess.run([*robocore, "init", str(project), "--defaults", "--base", "wheels"], check=True,
                   capture_output=True)
    for step in ("prepare-base", "stage", "build"):
        subprocess.run([*robocore, "-p", str(project), step, "--quiet"], check=True)
    time.sleep(2.5)  # files younger than the memo's trust limit would keep it from being written
    return project


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("project", nargs="?", type=Path)
    parser.add_argument("--runs", type=int, default=7)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="robocore-bench-noop-") as tmp:
        project = args.project.resolve() if args.project else ready_project(Path(tmp))
        py = sys.executable
        rows: list[tuple[str, float, float | None]] = []
        bare = median([py, "-c", "pass"], project, args.runs)
        rows.append(("python -c pass", bare, None))
        rows.append(("import robocore.cli", median([py, "-c", "import robocore.cli"], project, args.runs), None))
        for task in TASKS:
            argv = [py, "-m", "robocore", task]
            ordinary = median(argv, project, args.runs, ROBOCORE_NO_MEMO="1")
            memo = median(argv, project, args.runs)
            rows.append((task, ordinary, memo))
        print(f"no-op tasks on {project} (median of {args.runs}; machine shared, figures are noisy: "
              "compare within this run)")
        if os.environ.get("PYTHONDONTWRITEBYTECODE"):
            print("note: PYTHONDONTWRITEBYTECODE is set: modules without a __pycache__ entry are compiled from source "
                  "on every run (status without bytecode pays ~2x)")
        print(f"{'what':<22}{'ordinary':>10}{'memo':>10}{'x bare':>9}  goal < {GOAL} s; goal <= {GOAL_RATIO}x bare")
        figures = []
        for what, ordinary, memo in rows:
            best = memo if memo is not None else ordinary
            verdict = "" if what.startswith(("python", "import")) else (
                f"{'ok' if best < GOAL else 'MISSED'}; {'ok' if best / bare <= GOAL_RATIO else 'MISSED'}")
            memo_text = f"{memo:>9.3f}s" if memo is not None else f"{'-':>10}"
            print(f"{what:<22}{ordinary:>9.3f}s{memo_text}{best / bare:>8.1f}x  {verdict}")
            if memo is None:
                figures.append(Figure(what, ordinary, "s", ratio=ordinary / bare, ratio_of="x bare python"))
                continue
            figures.append(Figure(f"{what}, ordinary path", ordinary, "s", ratio=ordinary / bare,
                                  ratio_of="x bare python"))
            figures.append(Figure(f"{what}, no-op memo", memo, "s", f"< {GOAL} s or <= {GOAL_RATIO}x bare",
                                  memo / bare, "x bare python", memo < GOAL or memo / bare <= GOAL_RATIO,
                                  verdict.replace(";", " (< 0.3 s);") + " (ratio)"))
        record("noop", figures, goals=[f"validate, stage, build and status under {GOAL} s on an unchanged project "
                                       f"(on a loaded machine: <= {GOAL_RATIO}x bare Python's start-up)"],
               notes=[f"median of {args.runs} runs each" + ("" if args.project else
                                                            " on a new template project (wheels base)")])


if __name__ == "__main__":
    main()
