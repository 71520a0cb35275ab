"""Run every bench script in bench/ one after the other, then render docs/performance.md from their results.

Each script prints its own figures and ratios and writes bench/results/<name>.json. A script that fails is
reported and the others still run; the page is rendered from whatever results there are (a failed script's
previous result, if any, stays).

    python bench/run_all.py [NAME ...]     # only these benches (default: all)
"""

from __future__ import annotations

import argparse
import subprocess
import sys

from render_performance import BENCH, bench_names


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", metavar="NAME", help="bench scripts to run (default: all)")
    args = parser.parse_args()
    unknown = sorted(set(args.names) - set(bench_names()))
    if unknown:
        parser.error(f"no such bench: {', '.join(unknown)} (there are: {', '.join(bench_names())})")
    failed = []
    for name in args.names or bench_names():
        print(f"== {name}", flush=True)
        if subprocess.call([sys.executable, str(BENCH / f"{name}.py")]) != 0:
            failed.append(name)
    subprocess.check_call([sys.executable, str(BENCH / "render_performance.py")])
    if failed:
        print(f"failed: {', '.join(failed)}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
