"""CI's whole run, timed from a clean clone: each phase, and the integration session's minutes per module.

Clones this repository's HEAD into a new folder and runs ``.ci/run`` there as CI does (``CI=true``, no standard
input), with ``ROBOCORE_CI_TIMES`` set so that the integration session writes its table of where the minutes went
(integration/ci_times.py). Prints, side by side: the whole run against its goal, each phase (set-up, lint, types,
unit tests, integration), the integration session's busy CPU and the floor it sets on this machine's cores, and each
module's set-up, tests and wall time in its lane; writes them to bench/results/ci.json (``--warm``: ci-warm.json).

    python bench/ci.py --cold     # as on a new machine: FIRST REMOVES every container, image, volume, network and
                                  # the build cache of this Docker daemon, and the uv and pip caches
    python bench/ci.py --warm     # with the images the previous run left (the submitting machine's case)

The clone's output is kept in the clone's folder (``ci.log``), printed at the end with the table.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from harness import ROOT, Figure, record

#: Goals of the CI issue, in minutes.
COLD_GOAL, WARM_GOAL = 30, 20
#: The lines that start a phase in the output of scripts/test, and the phase's name.
PHASES = (("nox > Running session lint", "lint"), ("nox > Running session typecheck", "types"),
          ("nox > Running session tests", "unit tests"), ("nox > Running session integration", "integration"))
#: How many of the slowest modules get a row of their own.
MODULE_ROWS = 30


def make_cold() -> None:
    """Empty this machine's Docker daemon and the installers' caches, as a new machine has them."""
    subprocess.run(["docker", "swarm", "leave", "--force"], capture_output=True)
    ids = subprocess.run(["docker", "ps", "-aq"], capture_output=True, text=True).stdout.split()
    if ids:
        subprocess.run(["docker", "rm", "-f", "-v", *ids], capture_output=True)
    for argv in (["docker", "system", "prune", "-af", "--volumes"], ["docker", "builder", "prune", "-af"]):
        subprocess.run(argv, capture_output=True)
    for cache in (Path.home() / ".cache" / "uv", Path.home() / ".cache" / "pip"):
        shutil.rmtree(cache, ignore_errors=True)


def run_ci(clone: Path, times: Path) -> tuple[int, float, dict[str, float], list[str]]:
    """``.ci/run`` in ``clone``: its exit code, its seconds, each phase's start (seconds from the start) and its
    output lines."""
    env = {**os.environ, "CI": "true", "ROBOCORE_CI_TIMES": str(times)}
    env.pop("VIRTUAL_ENV", None)
    started = time.monotonic()
    starts: dict[str, float] = {}
    lines: list[str] = []
    with (clone / "ci.log").open("w") as log:
        proc = subprocess.Popen(["bash", ".ci/run"], cwd=clone, env=env, stdin=subprocess.DEVNULL,
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, errors="replace")
        assert proc.stdout is not None
        for line in proc.stdout:
            log.write(line)
            log.flush()
            lines.append(line.rstrip("\n"))
            for marker, phase in PHASES:
                if line.startswith(marker):
                    starts[phase] = time.monotonic() - started
        code = proc.wait()
    return code, time.monotonic() - started, starts, lines


def phase_figures(starts: dict[str, float], total: float) -> list[Figure]:
    """Each phase's seconds, from its start to the next one's (the set-up: before lint)."""
    order = [("set-up (venv, Debian tools)", 0.0)] + [(p, starts[p]) for _, p in PHASES if p in starts]
    out = []
    for (name, start), (_, end) in zip(order, [*order[1:], ("end", total)], strict=True):
        out.append(Figure(f"phase: {name}", end - start, "s"))
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    state = parser.add_mutually_exclusive_group(required=True)
    state.add_argument("--cold", action="store_true", help="empty the Docker daemon and caches first (see above)")
    state.add_argument("--warm", action="store_true", help="keep the images of earlier runs")
    parser.add_argument("--keep", action="store_true", help="keep the clone's folder (its ci.log) afterwards")
    args = parser.parse_args()

    if args.cold:
        print("emptying the Docker daemon and the uv and pip caches", flush=True)
        make_cold()
    parent = Path(tempfile.mkdtemp(prefix="robocore-ci-bench-"))
    clone = parent / "robocore"
    subprocess.run(["git", "clone", "-q", "--", str(ROOT), str(clone)], check=True)
    cloned = subprocess.run(["git", "-C", str(clone), "rev-parse", "HEAD"], capture_output=True, text=True,
                            check=True).stdout.strip()
    times = parent / "times.json"
    code, total, starts, lines = run_ci(clone, times)
    print("\n".join(lines[-80:]))

    goal = COLD_GOAL if args.cold else WARM_GOAL
    figures = [Figure(f"{'cold' if args.cold else 'warm'} CI run (.ci/run, exit {code})", total / 60, "min",
                      goal=f"< {goal} min", met=code == 0 and total < goal * 60, ratio=goal * 60 / total,
                      ratio_of="goal / time"),
               *phase_figures(starts, total)]
    # the record's own commit is this checkout's at the end, which may have moved on during the run
    notes = [f"ran on a clone of commit {cloned}"]
    if times.is_file():
        table = json.loads(times.read_text())
        floor = table["busy_cpu"] / table["cores"] if table.get("busy_cpu") else None
        figures.append(Figure("integration session: wall", table["wall"], "s",
                              detail=f"{len(table['modules'])} modules"))
        if floor is not None:
            figures.append(Figure("integration session: busy CPU over the cores (the floor)", floor, "s",
                                  ratio=floor / table["wall"], ratio_of="floor / wall",
                                  detail=f"{table['busy_cpu']:.0f} CPU-s on {table['cores']} cores"))
        for row in table["modules"][:MODULE_ROWS]:
            cpu = f", machine busy {row['busy_cpu']:.0f} CPU-s" if row.get("busy_cpu") is not None else ""
            figures.append(Figure(f"module {row['module'].removeprefix('integration/')}", row["wall"], "s",
                                  detail=f"lane {','.join(row['lanes'])}, {row['tests']} tests, starts at "
                                         f"{row['first_start']:.0f} s; set-up {row['setup']:.0f} s, tests "
                                         f"{row['call']:.0f} s, tear-down {row.get('teardown', 0):.0f} s, of which "
                                         f"held back by another lane {row.get('held_back', 0):.0f} s{cpu}"))
    else:
        notes.append("the integration session wrote no table (it did not run, or did not finish)")
    summary = [line for line in lines if re.search(r"\d+ (passed|failed)", line)]
    notes += [f"pytest: {line.strip('= ')}" for line in summary[-2:]]
    record("ci", figures, variant="" if args.cold else "warm", notes=notes,
           goals=[f"cold (new machine, empty daemon and caches) < {COLD_GOAL} min",
                  f"warm (the images of the last run present) < {WARM_GOAL} min"])
    if not args.keep:
        shutil.rmtree(parent, ignore_errors=True)
    else:
        print(f"kept {clone} (ci.log)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
