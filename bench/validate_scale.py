"""How long ``robocore validate`` takes on large and hostile robot.yaml files (goal: under 5 s each).

Each case writes a robot.yaml into a temporary project and runs ``robocore -p DIR validate`` as a
user would (a new process, start-up included). It prints the outcome (exit code and the first
line of output), the wall-clock time and its ratio to the 5 s goal, side by side:

- 6,000 hosts and 6,000 components whose ``runs_on`` names no host (every reference unknown);
- the same robot with every ``runs_on`` right (an accepted file of that size);
- a file just under 1 MB with as many components as fit; the same with every component wrong, and
  with a YAML syntax error on its last line; just under 1 MB of unknown keys; one just over 1 MB;
- deep nesting (``[`` a million times), a billion-laughs alias bomb, a 100,000-character host address.

    python bench/validate_scale.py [--keep DIR]
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from harness import Figure, record, robocore_command

GOAL_S = 5.0
MEGABYTE = 1_000_000
HEAD = "ros_distro: jazzy\n"


def many_hosts(count: int, *, known: bool) -> str:
    """``count`` hosts and ``count`` components, each on a host that exists only when ``known``."""
    lines = [HEAD, "hosts:\n"]
    lines += [f"  - {{name: h{i}, ip: 10.{i // 65536 % 256}.{i // 256 % 256}.{i % 256}}}\n" for i in range(count)]
    lines.append("components:\n")
    target = "h" if known else "x"
    lines += [f"  - {{name: c{i}, runs_on: {target}{i}, image: busybox}}\n" for i in range(count)]
    return "".join(lines)


def just_under_a_megabyte() -> str:
    """As many image components as fit in a file of just under 1 MB, all on one host."""
    head = HEAD + "hosts:\n  - {name: main, ip: 192.168.1.10}\ncomponents:\n"
    parts = [head]
    size = len(head)
    index = 0
    while True:
        line = f"  - {{name: c{index}, runs_on: main, image: 'ghcr.io/org/img:v1'}}\n"
        if size + len(line) >= MEGABYTE:
            break
        parts.append(line)
        size += len(line)
        index += 1
    return "".join(parts)


def every_component_wrong() -> str:
    """Just under 1 MB of components whose every value is refused (field errors, salvage, sorting)."""
    head = HEAD + "hosts:\n  - {name: main, ip: 192.168.1.10}\ncomponents:\n"
    line = "  - {{name: c{0}, runs_on: nowhere{0}, image: 'Bad Image', pip_packages: ['--index-url=x']}}\n"
    parts, size, index = [head], len(head), 0
    while size + len(line.format(index)) < MEGABYTE:
        parts.append(line.format(index))
        size += len(line.format(index))
        index += 1
    return "".join(parts)


def unknown_keys() -> str:
    """Just under 1 MB of unknown top-level keys (one pydantic error each)."""
    parts, size, index = [HEAD], len(HEAD), 0
    while size + len(f"key{index}: 1\n") < MEGABYTE - 100:
        parts.append(f"key{index}: 1\n")
        size += len(parts[-1])
        index += 1
    return "".join(parts) + "hosts:\n  - {name: main, ip: 192.168.1.10}\n"


def syntax_error_at_the_end() -> str:
    """Just under 1 MB of valid components, then a YAML syntax error on the last line."""
    return just_under_a_megabyte()[:-200] + "  - {name: broken, runs_on: [main\n"


def just_over_a_megabyte() -> str:
    """A valid file padded with a comment to just over 1 MB (refused before parsing)."""
    text = HEAD + "hosts:\n  - {name: main, ip: 192.168.1.10}\n"
    return text + "#" + "x" * (MEGABYTE - len(text)) + "\n"


def deep_nesting() -> str:
    """A value nested a million lists deep (just under 1 MB)."""
    return HEAD + "hosts: " + "[" * (MEGABYTE - 100) + "\n"


def alias_bomb() -> str:
    """Billion laughs: nine levels of nine aliases each (9**9 values when expanded)."""
    lines = [HEAD, 'a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]\n']
    for level in range(1, 10):
        refs = ", ".join([f"*a{level - 1}"] * 9)
        lines.append(f"a{level}: &a{level} [{refs}]\n")
    lines.append("hosts: *a9\n")
    return "".join(lines)


def long_address() -> str:
    """A host whose ip is 100,000 characters long."""
    return HEAD + f"hosts:\n  - {{name: main, ip: {'a' * 100_000}}}\n"


CASES: dict[str, Callable[[], str]] = {
    "6,000 hosts + 6,000 components, unknown runs_on": lambda: many_hosts(6000, known=False),
    "6,000 hosts + 6,000 components, all valid": lambda: many_hosts(6000, known=True),
    "just under 1 MB, as many components as fit": just_under_a_megabyte,
    "just under 1 MB, every component wrong": every_component_wrong,
    "just under 1 MB, YAML syntax error at the end": syntax_error_at_the_end,
    "just under 1 MB of unknown keys": unknown_keys,
    "just over 1 MB": just_over_a_megabyte,
    "deep nesting (a million '[')": deep_nesting,
    "billion-laughs alias bomb": alias_bomb,
    "100,000-character ip": long_address,
}


def run_case(root: Path, name: str, make: Callable[[], str]) -> tuple[int, str, float, int]:
    """Validate the case's file; returns exit code, first output line, seconds and the file size."""
    project = root / f"case-{abs(hash(name))}"
    project.mkdir(parents=True)
    text = make()
    (project / "robot.yaml").write_text(text, encoding="utf-8")
    env = dict(os.environ)
    start = time.perf_counter()
    done = subprocess.run([*robocore_command(), "-p", str(project), "validate"], capture_output=True, text=True,
                          env=env, timeout=600, check=False)
    seconds = time.perf_counter() - start
    output = (done.stderr + done.stdout).strip().splitlines()
    first = output[0] if output else ""
    if "Traceback" in done.stderr:
        first = "TRACEBACK: " + done.stderr.strip().splitlines()[-1]
    return done.returncode, first, seconds, len(text.encode("utf-8"))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--keep", type=Path, help="write the projects here and keep them")
    args = parser.parse_args()
    root = args.keep or Path(tempfile.mkdtemp(prefix="robocore-validate-scale-"))
    failed = 0
    figures: list[Figure] = []
    print(f"{'case':<50} {'size':>10} {'exit':>4} {'time':>8} {'goal':>6} {'goal/time':>9}  first line")
    try:
        for name, make in CASES.items():
            code, first, seconds, size = run_case(root, name, make)
            ok = seconds < GOAL_S and code in (0, 2) and not first.startswith("TRACEBACK")
            failed += not ok
            print(f"{name:<50} {size:>10,} {code:>4} {seconds:>7.2f}s {GOAL_S:>5.1f}s {GOAL_S / seconds:>8.1f}x  "
                  f"{first[:110]}{'' if ok else '   <-- over the goal or not a clean refusal'}", flush=True)
            figures.append(Figure(name, seconds, "s", f"< {GOAL_S:g} s, a clean exit", GOAL_S / seconds, "goal / time",
                                  ok, f"{size:,} bytes, exit {code}"))
    finally:
        if args.keep is None:
            shutil.rmtree(root, ignore_errors=True)
    record("validate_scale", figures, goals=[f"each case refused or accepted (exit 0 or 2, no traceback) in under "
                                             f"{GOAL_S:g} s, start-up included"])
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
