"""How long each refusal of a hostile project takes (goal: under 5 s each, on 2 cores).

Each case sets up a hostile project in a temporary folder and runs ``robocore -p DIR TASK`` as a user would
(a new process, start-up included; ``DOCKER_HOST`` points at a socket nobody serves, so no case reaches a
daemon). It prints the outcome (exit code and the first line of stderr), the wall-clock time, the CPU time of the
process, and the ratios to the 5 s goal and to the reference (a plain ``validate`` of a small good project,
measured first in the same run), side by side:

- aliases that expand a 300 kB scalar past the byte limit; a billion-laughs bomb past the value limit;
- robot.yaml as a FIFO (a plain reader would wait for ever), as ``/dev/zero``, as a link out of the project;
- ``.robocore``, ``.robocore/compose`` and ``.robocore/dds`` as links to a folder outside (stage --refresh,
  build), a package.xml FIFO (stage --dry-run);
- a relative volume that leaves the project; ``--dry-run`` on a line with a task that has none;
- a link to ``/usr`` in the project, ``.robocore/noop`` linked outside, the memo as a FIFO and as a link
  to ``/dev/zero`` (each reproduction hung, ran out of memory or took 7-24 s before), a 120,000-character
  ``--component`` and an empty ``--host``.

    python bench/hostile_limits.py
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from harness import Figure, record

GOAL_S = 5.0
GOOD = """\
ros_distro: jazzy
hosts:
  - {name: dev, ip: 127.0.0.1}
components:
  - {name: talker, folder: components/talker, runs_on: dev}
"""


def project(root: Path, text: str = GOOD) -> Path:
    pkg = root / "components" / "talker" / "src" / "talker_pkg"
    pkg.mkdir(parents=True)
    (pkg / "package.xml").write_text("<package><name>talker_pkg</name></package>")
    (root / "robot.yaml").write_text(text)
    return root


def link_state(root: Path, rel: str) -> Path:
    outside = root.parent / "outside"
    outside.mkdir(exist_ok=True)
    (outside / "canary").write_text("canary\n")
    (root / rel).parent.mkdir(parents=True, exist_ok=True)
    (root / rel).symlink_to(outside)
    return root


def robot_as(root: Path, kind: str) -> Path:
    project(root)
    robot = root / "robot.yaml"
    robot.unlink()
    if kind == "fifo":
        os.mkfifo(robot)
    elif kind == "device":
        robot.symlink_to("/dev/zero")
    else:
        outside = root.parent / "outside.yaml"
        outside.write_text(GOOD)
        robot.symlink_to(outside)
    return root


def memo_as(root: Path, kind: str) -> Path:
    """Something planted at the name of ``validate``'s memo (predictable from the project's path)."""
    from robocore.commands.support import noop

    project(root)
    path = noop.Memo(root, "validate", [], line=[str(Path.cwd()), "-p", str(root), "validate"]).path
    path.parent.mkdir(parents=True)
    if kind == "fifo":
        os.mkfifo(path)
    else:
        path.symlink_to("/dev/zero")
    return root


def link_to_usr(root: Path) -> Path:
    project(root)
    (root / "extlink").symlink_to("/usr", target_is_directory=True)
    return root


def package_fifo(root: Path) -> Path:
    project(root)
    manifest = root / "components" / "talker" / "src" / "talker_pkg" / "package.xml"
    manifest.unlink()
    os.mkfifo(manifest)
    return root


BYTES_BOMB = "big: &big " + "x" * 300_000 + "\nhosts: [*big, *big, *big, *big, *big, *big, *big]\n"
VALUES_BOMB = "a0: &a0 [x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]\n" for i in range(1, 10))
OUT_VOLUME = GOOD.replace("runs_on: dev}", "runs_on: dev, volumes: ['./../../var/run/docker.sock:/s']}")

CASES: list[tuple[str, Callable[[Path], Path], list[str]]] = [
    ("reference: validate, small good project", project, ["validate"]),
    ("alias expands past the byte limit", lambda r: project(r, BYTES_BOMB), ["validate"]),
    ("alias bomb past the value limit", lambda r: project(r, VALUES_BOMB), ["validate"]),
    ("robot.yaml is a FIFO", lambda r: robot_as(r, "fifo"), ["validate"]),
    ("robot.yaml is /dev/zero", lambda r: robot_as(r, "device"), ["validate"]),
    ("robot.yaml links out of the project", lambda r: robot_as(r, "link"), ["validate"]),
    (".robocore links outside: stage --refresh", lambda r: link_state(project(r), ".robocore"), ["stage", "--refresh"]),
    (".robocore/compose links outside: stage --refresh", lambda r: link_state(project(r), ".robocore/compose"),
     ["stage", "--refresh"]),
    (".robocore/dds links outside: build", lambda r: link_state(project(r), ".robocore/dds"), ["build"]),
    ("package.xml is a FIFO: stage --dry-run", package_fifo, ["stage", "--dry-run"]),
    ("relative volume leaves the project", lambda r: project(r, OUT_VOLUME), ["validate"]),
    ("extlink -> /usr in the project: validate", link_to_usr, ["validate"]),
    (".robocore/noop links outside: validate", lambda r: link_state(project(r), ".robocore/noop"), ["validate"]),
    ("the memo is a FIFO: validate", lambda r: memo_as(r, "fifo"), ["validate"]),
    ("the memo links to /dev/zero: validate", lambda r: memo_as(r, "device"), ["validate"]),
    ("--component of 120,000 characters: logs --dry-run", project, ["logs", "--component", "x" * 120_000,
                                                                   "--dry-run"]),
    ("--host '': down --dry-run", project, ["down", "--host", "", "--dry-run"]),
    ("--dry-run line with doctor", project, ["stage", "--dry-run", "doctor"]),
]


def main() -> int:
    print(f"{'case':50} {'exit':>4} {'wall s':>7} {'cpu s':>6} {'/ goal':>6} {'/ ref':>6}  first line")
    worst = 0.0
    reference = None
    figures: list[Figure] = []
    with tempfile.TemporaryDirectory(prefix="robocore-hostile-bench-") as tmp:
        env = dict(os.environ, DOCKER_HOST=f"unix://{tmp}/nobody.sock")
        for index, (name, setup, task) in enumerate(CASES):
            root = setup(Path(tmp) / f"case{index}" / "robot")
            start, before = time.monotonic(), resource.getrusage(resource.RUSAGE_CHILDREN)
            try:
                done = subprocess.run([sys.executable, "-m", "robocore", "-p", str(root), *task], capture_output=True,
                                      text=True, env=env, timeout=60, stdin=subprocess.DEVNULL)
                code, first = done.returncode, (done.stderr or done.stdout).strip().splitlines()[:1]
            except subprocess.TimeoutExpired:
                code, first = -1, ["TIMEOUT after 60 s"]
            seconds = time.monotonic() - start
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
            reference = reference or seconds
            worst = max(worst, seconds)
            print(f"{name:50} {code:>4} {seconds:7.2f} {cpu:6.2f} {seconds / GOAL_S:6.2f} {seconds / reference:6.2f}  "
                  f"{(first or [''])[0][:100]}", flush=True)
            figures.append(Figure(name, seconds, "s", f"< {GOAL_S:g} s", seconds / reference, "x reference",
                                  seconds < GOAL_S and code != -1, f"exit {code}, CPU {cpu:.2f} s"))
    print(f"worst: {worst:.2f} s wall ({worst / GOAL_S:.2f} of the {GOAL_S:.0f} s goal); load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (a shared machine inflates wall times)")
    record("hostile_limits", figures, goals=[f"each hostile project refused in under {GOAL_S:g} s on 2 cores, "
                                             "start-up included"],
           notes=[f"worst {worst:.2f} s wall; the reference is a plain validate of a small good project, measured "
                  "first in the same run"])
    return 0 if worst < GOAL_S else 1


if __name__ == "__main__":
    sys.exit(main())
