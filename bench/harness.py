"""What every bench script shares: running the robocore CLI, and recording the figures it measured.

A bench script imports this module as it starts (``python bench/x.py`` puts bench/ first on ``sys.path``), so
the moment of that import is the start of the run: its wall-clock time and the machine's load average are taken
then. At the end the script calls :func:`record` with its figures; that writes ``bench/results/<name>.json``:

- ``command``: the command line as run (``python bench/x.py ARGS``, from the repository's root), to reproduce it;
- ``date`` (UTC), ``seconds`` (the whole run), ``commit`` (and whether robocore/ or bench/ had changes not
  committed);
- ``machine``: CPU model and count, memory, kernel, Python, the Docker server's version if one answers, and the
  load average at the start and at the end (the machine is shared: a high load inflates wall-clock figures);
- ``figures``: rows of label, value, unit, goal, ratio (and what the ratio compares), the script's verdict
  against the goal and a detail; ``goals`` and ``notes``: sentences about the run as a whole.

``python bench/render_performance.py`` renders docs/performance.md from those files. ``ROBOCORE_BENCH_RESULTS``
names another folder to write to (a trial run that should not replace the recorded figures).
"""

from __future__ import annotations

import json
import os
import platform
import shlex
import subprocess
import sys
import time
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass
from datetime import datetime, timezone
from pathlib import Path

BENCH = Path(__file__).resolve().parent
ROOT = BENCH.parent
#: Where :func:`record` writes, one file per bench script.
RESULTS = BENCH / "results"
#: The start of the run: this module is imported as a bench script starts.
STARTED = time.time()
LOAD_AT_START = os.getloadavg()


def robocore(project: Path | None, *args: str, check: bool = True, timeout: float | None = None,
             python: Sequence[str] = (), env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    """Run ``python -m robocore [-p PROJECT] ARGS`` as a user would (a new process), its output captured.

    ``check``: a non-zero exit stops the bench with the command, the exit code and the output's tails.
    ``python``: options for the interpreter before ``-m robocore`` (e.g. ``-m cProfile -o FILE``).
    ``env``: the process's environment (default: this one's).
    """
    argv = [sys.executable, *python, "-m", "robocore", *(["-p", str(project)] if project else []), *args]
    done = subprocess.run(argv, capture_output=True, text=True, check=False, timeout=timeout, env=env)
    if check and done.returncode != 0:
        raise SystemExit(f"robocore {' '.join(args)} failed ({done.returncode}):\n{done.stdout[-3000:]}\n"
                         f"{done.stderr[-3000:]}")
    return done


def copy_built_project(source: Path, root: Path) -> None:
    """Make ``root`` a copy of the built project ``source`` (its install trees and state; not its test runs), so a
    bench edits its robot.yaml without touching the original."""
    subprocess.run(["rsync", "-a", "--delete", "--exclude", ".robocore/test-runs", f"{source}/", f"{root}/"],
                   check=True)


def robocore_command() -> list[str]:
    """The installed console script next to this Python (what a user types), else ``python -m robocore``."""
    script = Path(sys.executable).with_name("robocore")
    return [str(script)] if script.exists() else [sys.executable, "-m", "robocore"]


@dataclass(frozen=True)
class Figure:
    """One measured figure: a row of the performance page.

    ``goal`` is the target as text (``"< 5 s"``); ``met`` the script's own verdict against it (None: no goal).
    ``ratio`` is the figure the script prints beside the value, and ``ratio_of`` says what it compares
    (``"x bare python"``, ``"goal / time"``).
    """

    label: str
    value: float | int | str | None
    unit: str = ""
    goal: str | None = None
    ratio: float | None = None
    ratio_of: str = ""
    met: bool | None = None
    detail: str = ""


def record(name: str, figures: Iterable[Figure], *, goals: Sequence[str] = (), notes: Sequence[str] = (),
           variant: str = "") -> Path:
    """Write ``bench/results/<name>.json``: the figures of this run with its command, date, commit and machine.

    ``name`` is the bench script's name (``bench/<name>.py``). ``variant`` names a run that measures something
    else with the same script (another ROS distro): it gets a file of its own, ``<name>-<variant>.json``, so that
    both stay on the performance page. Returns the file written.
    """
    if not (BENCH / f"{name}.py").is_file():
        raise ValueError(f"{name}: no bench/{name}.py")
    if variant and not variant.replace("_", "").isalnum():
        raise ValueError(f"{variant!r}: a variant is letters, digits and underscores")
    if os.environ.get("PYTHONDONTWRITEBYTECODE"):
        notes = [*notes, "PYTHONDONTWRITEBYTECODE was set: modules without bytecode were compiled on every start"]
    main = sys.modules.get("__main__")
    doc = (getattr(main, "__doc__", None) or "").strip()
    result = {
        "bench": name,
        **({"variant": variant} if variant else {}),
        "title": doc.splitlines()[0] if doc else "",
        "command": command_line(sys.argv),
        "date": datetime.fromtimestamp(STARTED, tz=timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "seconds": round(time.time() - STARTED, 1),
        **commit(),
        "machine": machine(),
        "goals": list(goals),
        "notes": list(notes),
        "figures": [{k: rounded(v) for k, v in asdict(f).items() if v not in (None, "")} for f in figures],
    }
    folder = Path(os.environ.get("ROBOCORE_BENCH_RESULTS") or RESULTS)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / (f"{name}-{variant}.json" if variant else f"{name}.json")
    partial = path.with_name(f".{path.name}.partial")
    partial.write_text(json.dumps(result, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")
    partial.replace(path)
    print(f"result written to {path}", flush=True)
    return path


def rounded(value: object) -> object:
    """A float to 4 significant digits (more than any bench's noise allows); anything else as it is."""
    return float(f"{value:.4g}") if isinstance(value, float) else value


def command_line(argv: Sequence[str]) -> str:
    """``argv`` as a command to type in the repository's root: ``python bench/x.py ARGS``."""
    script = Path(argv[0]).resolve()
    shown = str(script.relative_to(ROOT)) if script.is_relative_to(ROOT) else argv[0]
    return shlex.join(["python", shown, *argv[1:]])


def commit() -> dict[str, object]:
    """The commit checked out and whether robocore/ or bench/ (its results aside) differ from it."""
    def git(*args: str) -> str:
        done = subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True, check=False)
        return done.stdout.strip() if done.returncode == 0 else ""

    changed = git("status", "--porcelain", "--", "robocore", "bench", ":!bench/results")
    return {"commit": git("rev-parse", "HEAD") or None, "uncommitted_changes": bool(changed)}


def machine() -> dict[str, object]:
    """CPU, memory, kernel, Python and Docker of this machine, and its load average at the start and now."""
    cpu = ""
    with open("/proc/cpuinfo", encoding="utf-8") as info:
        for line in info:
            if line.startswith("model name"):
                cpu = line.partition(":")[2].strip()
                break
    memory = 0.0
    with open("/proc/meminfo", encoding="utf-8") as info:
        for line in info:
            if line.startswith("MemTotal:"):
                memory = int(line.split()[1]) / 1024 / 1024
                break
    return {
        "cpu": cpu or platform.processor(),
        "cores": os.cpu_count(),
        "memory_gib": round(memory, 1),
        "kernel": f"{platform.system()} {platform.release()}",
        "python": platform.python_version(),
        "docker": docker_version(),
        "load_at_start": [round(x, 2) for x in LOAD_AT_START],
        "load_at_end": [round(x, 2) for x in os.getloadavg()],
    }


def docker_version() -> str | None:
    """The local Docker server's version, or None when no daemon answers within 10 s."""
    try:
        done = subprocess.run(["docker", "version", "--format", "{{.Server.Version}}"], capture_output=True,
                              text=True, timeout=10, check=False)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return done.stdout.strip() or None if done.returncode == 0 else None
