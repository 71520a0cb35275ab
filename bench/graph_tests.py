"""Graph tests of a template project: robocore's pytest plugin beside the present way, and its flakiness.

In one run, on a project made by ``robocore init --defaults --base wheels`` (built once first):

1. bring-up: from starting pytest to the first /chatter message at the test process's probe,
   with the images built during it (0 when warm); beside it the present way, ``robocore run``
   then polling ``robocore logs`` until the listener prints a message, then ``robocore down``;
2. per-test overhead: 20 tests that each use ``robot`` minus the same 20 tests without it;
3. the template's own ``tests/graph`` run N times in a row (default 20), counting failures;
4. the template's ``nox --no-venv -s graph``, warm.

Goals: bring-up < 5 s warm; ``nox -s graph`` < 60 s warm on 2 cores; 0 failures in 20 runs.
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

from harness import Figure, record, robocore

PYTEST = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q"]
FIRST_MESSAGE = '''
import time
from std_msgs.msg import String

def test_first_message(robot):
    robot.graph.wait_for_message("/chatter", String, timeout=60)
    with open({path!r}, "w") as out:
        out.write(repr(time.time()))
'''
MANY = '''
import pytest

@pytest.mark.parametrize("n", range(20))
def test_uses_the_robot(robot, n):
    assert robot.graph.node is not None
'''
PLAIN = '''
import pytest

@pytest.mark.parametrize("n", range(20))
def test_plain(n):
    assert n >= 0
'''


def images_since(start: float) -> int:
    out = subprocess.run(["docker", "images", "--format", "{{.CreatedAt}}", "--filter", "label=dev.robocore.inputs"],
                         capture_output=True, text=True, check=True).stdout
    count = 0
    for line in out.splitlines():
        stamp = " ".join(line.split()[:2])
        created = time.mktime(time.strptime(stamp, "%Y-%m-%d %H:%M:%S"))
        count += created >= int(start)
    return count


def bring_up(project: Path, scratch: Path) -> tuple[float, int]:
    marker = scratch / "first-message"
    marker.unlink(missing_ok=True)
    test = scratch / "test_first_message.py"
    test.write_text(FIRST_MESSAGE.format(path=str(marker)))
    start = time.time()
    subprocess.run([*PYTEST, "--robocore-project", str(project), str(test)], check=True, capture_output=True,
                   cwd=scratch)
    return float(marker.read_text()) - start, images_since(start)


def present_way(project: Path) -> float:
    """``robocore run``, then ``robocore logs`` polled until the listener heard a message."""
    start = time.time()
    robocore(project, "run", "--quiet")
    try:
        while "I heard" not in robocore(project, "logs", "--component", "listener", "--tail", "5").stdout:
            if time.time() - start > 120:
                raise RuntimeError("the listener never heard the talker")
            time.sleep(0.2)
        return time.time() - start
    finally:
        robocore(project, "down", "--quiet")


def timed_pytest(argv: list[str], cwd: Path) -> tuple[float, subprocess.CompletedProcess[str]]:
    start = time.perf_counter()
    proc = subprocess.run(argv, capture_output=True, text=True, cwd=cwd)
    return time.perf_counter() - start, proc


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3, help="bring-up rounds per way (median shown)")
    parser.add_argument("--repeat", type=int, default=20, help="runs of the template's tests/graph")
    args = parser.parse_args()
    # the template's nox sessions call robocore and pytest: those of this interpreter's environment
    os.environ["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"
    scratch = Path(tempfile.mkdtemp(prefix="robocore-bench-graph-"))
    project = scratch / "robocore-bench-graph"
    subprocess.run([sys.executable, "-m", "robocore", "init", str(project), "--defaults", "--base", "wheels"],
                   check=True, capture_output=True)
    for step in ("prepare-base", "stage", "build"):
        robocore(project, step, "--quiet")
    if not (project / "tests" / "graph").is_dir():
        print("the template has no tests/graph: nothing to repeat")
        return 1

    ours = [bring_up(project, scratch) for _ in range(args.rounds)]
    theirs = [present_way(project) for _ in range(args.rounds)]
    ours_median = statistics.median(t for t, _ in ours)
    theirs_median = statistics.median(theirs)
    print(f"bring-up to the first message, median of {args.rounds} (goal < 5 s warm):")
    print(f"  robocore.testing (pytest start -> message at the probe): {ours_median:5.2f} s  "
          f"(runs: {', '.join(f'{t:.2f}' for t, _ in ours)}; images built: {', '.join(str(n) for _, n in ours)})")
    print(f"  robocore run + polling robocore logs:                    {theirs_median:5.2f} s  "
          f"(runs: {', '.join(f'{t:.2f}' for t in theirs)})")
    print(f"  ratio: {theirs_median / ours_median:.1f}x")

    (scratch / "test_many.py").write_text(MANY)
    (scratch / "test_plain.py").write_text(PLAIN)
    with_robot, _ = timed_pytest([*PYTEST, "--robocore-project", str(project), "test_many.py"], scratch)
    plain, _ = timed_pytest([*PYTEST, "test_plain.py"], scratch)
    single, _ = timed_pytest([*PYTEST, "--robocore-project", str(project), "test_many.py", "-k", "0]"], scratch)
    per_test = (with_robot - single) / 19
    print(f"per-test overhead of robot (20 tests {with_robot:.2f} s, 1 test {single:.2f} s, "
          f"20 plain tests {plain:.2f} s): {per_test * 1000:.0f} ms")

    failures = 0
    durations = []
    for index in range(args.repeat):
        seconds, proc = timed_pytest([*PYTEST, "tests/graph"], project)
        durations.append(seconds)
        if proc.returncode != 0:
            failures += 1
            print(f"  run {index + 1} failed:\n{proc.stdout[-3000:]}")
    print(f"template tests/graph x{args.repeat}: {failures} failed (goal 0); "
          f"median {statistics.median(durations):.2f} s, max {max(durations):.2f} s")

    if not (project / "noxfile.py").exists():
        print("the template has no noxfile.py")
        return 1
    seconds, proc = timed_pytest([sys.executable, "-m", "nox", "--no-venv", "-s", "graph"], project)
    status = "ok" if proc.returncode == 0 else f"FAILED\n{proc.stdout[-2000:]}{proc.stderr[-2000:]}"
    print(f"nox --no-venv -s graph, warm: {seconds:.1f} s (goal < 60 s): {status}")
    record("graph_tests", [
        Figure("bring-up to the first message: robocore.testing", ours_median, "s", "< 5 s warm",
               met=ours_median < 5, detail=f"runs {', '.join(f'{t:.2f}' for t, _ in ours)}; images built "
                                           f"{', '.join(str(n) for _, n in ours)}"),
        Figure("bring-up to the first message: robocore run + polling robocore logs", theirs_median, "s",
               ratio=theirs_median / ours_median, ratio_of="x robocore.testing",
               detail=f"runs {', '.join(f'{t:.2f}' for t in theirs)}"),
        Figure("per-test overhead of robot", per_test * 1000, "ms",
               detail=f"20 tests {with_robot:.2f} s, 1 test {single:.2f} s, 20 plain tests {plain:.2f} s"),
        Figure(f"template tests/graph x{args.repeat}: failures", failures, "", "0", met=failures == 0,
               detail=f"median {statistics.median(durations):.2f} s, max {max(durations):.2f} s"),
        Figure("nox --no-venv -s graph, warm", seconds, "s", "< 60 s", met=seconds < 60 and proc.returncode == 0,
               detail="ok" if proc.returncode == 0 else "FAILED"),
    ], goals=["bring-up < 5 s warm", "nox -s graph < 60 s warm on 2 cores", f"0 failures in {args.repeat} runs"],
        notes=[f"bring-up: median of {args.rounds} rounds per way"])
    return 1 if failures or proc.returncode else 0


if __name__ == "__main__":
    sys.exit(main())
