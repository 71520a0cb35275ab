"""Start-up time of ``robocore --help`` (target: median under 0.3 s).

Runs ``robocore --help`` N times through subprocess and prints median, min and max next to a
bare ``python -c pass`` and ``python -c "import invoke"``, with the ratios between them, plus the
modules the help imports that it should not need.

    python bench/startup.py [-n 20]
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import time

from harness import Figure, record, robocore_command

TARGET_S = 0.3
HEAVY = ("pydantic", "docker", "copier", "rich", "paramiko")


def timed(argv: list[str], runs: int) -> tuple[list[float], list[float]]:
    """Wall-clock and CPU (user+sys) seconds of ``runs`` runs of ``argv``; a failure stops the bench.

    CPU time hardly moves when other work shares the machine; wall time does.
    """
    wall, cpu = [], []
    for _ in range(runs):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
        wall.append(time.perf_counter() - start)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return wall, cpu


def heavy_imports() -> list[str]:
    """Heavy libraries that ``robocore --help`` imports (should be none)."""
    code = (
        "import sys\nfrom robocore.cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
        f"print(','.join(m for m in {HEAVY!r} if m in sys.modules))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    last = done.stdout.strip().splitlines()[-1] if done.stdout.strip() else ""
    return [m for m in last.split(",") if m in HEAVY]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", "--runs", type=int, default=20)
    args = parser.parse_args()
    command = robocore_command()
    cases = {
        "python -c pass": [sys.executable, "-c", "pass"],
        "python -c 'import invoke'": [sys.executable, "-c", "import invoke"],
        "robocore --help": [*command, "--help"],
    }
    timed(cases["robocore --help"], 2)  # warm the page cache and __pycache__
    results = {name: timed(argv, args.runs) for name, argv in cases.items()}
    bare = statistics.median(results["python -c pass"][0])
    bare_cpu = statistics.median(results["python -c pass"][1])
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; n={args.runs}; seconds")
    print(f"{'command':<28} {'median':>8} {'min':>8} {'max':>8} {'x bare':>7} {'cpu med':>8} {'cpu x bare':>10}")
    figures = []
    for name, (wall, cpu) in results.items():
        median, cpu_median = statistics.median(wall), statistics.median(cpu)
        print(f"{name:<28} {median:8.3f} {min(wall):8.3f} {max(wall):8.3f} {median / bare:7.2f} "
              f"{cpu_median:8.3f} {cpu_median / bare_cpu:10.2f}")
        target = name == "robocore --help"
        figures.append(Figure(f"{name}, median", median, "s", f"< {TARGET_S:g} s" if target else None,
                              median / bare, "x bare python", median < TARGET_S if target else None,
                              f"min {min(wall):.3f} s, max {max(wall):.3f} s; CPU {cpu_median:.3f} s, "
                              f"{cpu_median / bare_cpu:.2f}x bare"))
    help_median = statistics.median(results["robocore --help"][0])
    verdict = "ok" if help_median < TARGET_S else "over target (check the load average above)"
    print(f"robocore --help median {help_median:.3f} s vs target {TARGET_S:.1f} s: {verdict} "
          f"({help_median / TARGET_S:.0%} of the budget; robocore's own share over bare python "
          f"{help_median - bare:.3f} s)")
    heavy = heavy_imports()
    print("heavy modules imported by --help: " + (", ".join(heavy) if heavy else "none"))
    figures.append(Figure("heavy modules imported by --help", ", ".join(heavy) or "none", goal="none",
                          met=not heavy, detail=f"of {', '.join(HEAVY)}"))
    record("startup", figures, goals=[f"robocore --help median under {TARGET_S:g} s", "no heavy module imported"],
           notes=[f"{args.runs} runs of each command"])
    # timing is reported, not enforced (a loaded machine inflates it); importing a heavy library is a bug
    return 1 if heavy else 0


if __name__ == "__main__":
    sys.exit(main())
