"""A Swarm fleet's faults on the fleet's side: robots left without a healthy release, and the time to a healthy fleet.

Measured by the Swarm suite's own fault tests (integration/test_fleet_swarm.py, on its DinD swarm: a manager of its
own, robots on robot hosts, the TLS registry with a login), which write their figures to the file
``ROBOCORE_FAULT_FIGURES`` names:

1. the registry down during a wave: the canary of the one-host fleet (four robots) cannot pull v4, fails its gate
   and goes back to v2; no later wave is touched. Time: from the rollout's start to the command's end (the
   canary back and gated);
2. the manager's daemon restarted in the middle of the two-host fleet's rollout (two robots): the rollout that lost
   it ends, and is run again once the manager answers. Time: from the first rollout's start to the end of the one
   run again (the manager's downtime included);
3. a robot host's power cut in its update (the two-host fleet, r5's main host killed, booted once the manager saw
   it down): the rollout reports it pending; Swarm brings it to the target once it is back, and the rollout run
   again gates it. Time: from the rollout's start to the end of the one run again.

A robot without a healthy release is one not running its target or whose last gate did not pass (goal: 0 after
each fault, once the documented recovery has run: docs/fleets.md, "Faults on the fleet's side").

By default this runs the Swarm suite's fault tests and what they stand on (the join, v1 and v2 to every robot;
about 8 min on a 2-core machine, real Docker, one lane) and records what they wrote; ``--from FILE`` records the
figures an earlier run of the suite wrote to FILE (run with ROBOCORE_FAULT_FIGURES=FILE).

    python bench/fleet_faults.py [--from FILE] [-k EXPRESSION] [--note TEXT]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from harness import Figure, record

ROOT = Path(__file__).resolve().parent.parent
#: The Swarm suite's fault tests and the tests whose state they start from.
SELECTION = ("join_labels or v1_rolls_out or v2_reaches or registry_down or managers_restart or "
             "power_is_cut")
#: What each fault's figures say of its time, and of the seconds measured beside it.
FAULTS = {
    "registry down during a wave": ("from the rollout's start to its end (the canary back, gated)", {}),
    "manager restarted mid-rollout": ("from the first rollout's start to the end of the one run again", {
        "manager_down": "the manager down {:.1f} s",
        "finished_after_manager_back": "finished {:.1f} s after the manager answered again"}),
    "robot host power cut mid-update": ("from the rollout's start to the end of the one run again", {
        "power_off": "the host off {:.1f} s",
        "on_target_after_boot": "on the target {:.1f} s after its boot, with no command"}),
}


def figures(lines: list[dict[str, Any]]) -> list[Figure]:
    """The performance page's rows for the faults' figures (the last of each fault's lines), in :data:`FAULTS`'s
    order."""
    last = {line["fault"]: line for line in lines}
    out = []
    for fault, (timed, said) in FAULTS.items():
        line = last.get(fault)
        if line is None:
            continue
        out.append(Figure(f"{fault}: robots left without a healthy release", line["left"], "robots", goal="0",
                          met=line["left"] == 0, detail=f"of {line['robots']}"))
        extra = [text.format(line[key]) for key, text in said.items() if key in line]
        out.append(Figure(f"{fault}: healthy fleet after", line["healthy"], "s",
                          detail="; ".join([timed, *extra])))
    return out


def read(path: Path) -> list[dict[str, Any]]:
    """The JSON lines the fault tests wrote to ``path``."""
    return [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines() if line.strip()]


def run_suite(selection: str, into: Path) -> int:
    """Run the Swarm suite's tests of ``selection`` in one lane, their figures written to ``into``; pytest's exit
    code."""
    # the robocore of this checkout, in the suite and in the commands it runs
    path = os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])
    env = {**os.environ, "ROBOCORE_IT_LANES": "0", "ROBOCORE_FAULT_FIGURES": str(into), "PYTHONPATH": path}
    argv = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-s",
            "integration/test_fleet_swarm.py", "-k", selection]
    return subprocess.run(argv, cwd=ROOT, env=env, check=False).returncode


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--from", dest="source", type=Path, help="record the figures a run of the suite wrote here")
    parser.add_argument("-k", dest="selection", default=SELECTION, help="the suite's tests to run")
    parser.add_argument("--note", action="append", default=[], help="a note for the result (e.g. which runs wrote "
                        "the figures of --from)")
    args = parser.parse_args()
    notes = list(args.note)
    if args.source is not None:
        lines = read(args.source)
        notes.append(f"figures written by a run of integration/test_fleet_swarm.py ({args.source.name})")
    else:
        with tempfile.TemporaryDirectory(prefix="robocore-faults-") as folder:
            into = Path(folder) / "figures.jsonl"
            into.touch()
            code = run_suite(args.selection, into)
            lines = read(into)
        notes.append(f"integration/test_fleet_swarm.py -k '{args.selection}': pytest exited {code}")
    table = figures(lines)
    if not table:
        raise SystemExit("no fault test wrote its figures")
    width = max(len(f.label) for f in table)
    for figure in table:
        print(f"{figure.label:<{width}}  {figure.value:>6} {figure.unit:<6}  {figure.detail}")
    missing = [fault for fault in FAULTS if fault not in {line["fault"] for line in lines}]
    notes += [f"not measured in this run: {fault}" for fault in missing]
    record("fleet_faults", table, goals=["0 robots left without a healthy release after each fault"], notes=notes)


if __name__ == "__main__":
    main()
