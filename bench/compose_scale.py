"""How long the compose files of a 10,000-component robot take to write (goal: under 3 s).

One robot.yaml with N image components on two hosts (default 10,000) is loaded once; then, in one process and
side by side, each step of ``stage --refresh``'s compose writing is timed: the container specs, the compose
documents (the spec hash of every container included), the YAML text with PyYAML's pure-Python emitter, with
libyaml's, and with robocore's direct writer (the same text: plan/yaml_text.py), and the whole
``write_compose_files``. A machine shared with other work inflates every wall-clock figure alike: compare the rows
of one run, and the CPU time (``time.process_time``) beside each, which the load inflates less.

    python bench/compose_scale.py [--components N]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import yaml
from harness import Figure, record

from robocore.commands.support.composefiles import write_compose_files
from robocore.commands.support.state import with_local_build
from robocore.plan import compose, yaml_text
from robocore.plan.containers import host_specs
from robocore.project import Project

GOAL_S = 3.0


def robot_yaml(count: int) -> str:
    lines = ["ros_distro: jazzy\nhosts:\n  - {name: main, ip: 192.168.1.10}\n  - {name: pi, ip: 192.168.1.20}\n"
             "components:\n"]
    lines += [f"  - {{name: c{i}, runs_on: {'main' if i % 2 else 'pi'}, image: 'ghcr.io/org/img:v1'}}\n"
              for i in range(count)]
    return "".join(lines)


def timed(label: str, step: object) -> tuple[float, float, object]:
    start, cpu = time.perf_counter(), time.process_time()
    result = step()  # type: ignore[operator]
    seconds, cpu = time.perf_counter() - start, time.process_time() - cpu
    print(f"{label:58} {seconds:7.2f} s  CPU {cpu:6.2f} s", flush=True)
    return seconds, cpu, result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--components", type=int, default=10_000)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="robocore-bench-compose-") as tmp:
        root = Path(tmp) / "robot"
        root.mkdir()
        (root / "robot.yaml").write_text(robot_yaml(args.components))
        print(f"{args.components:,} components on 2 hosts; libyaml: {yaml.__with_libyaml__}; "
              f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
        _, _, project = timed("load and validate robot.yaml (not part of the goal)", lambda: Project.load(root))
        assert isinstance(project, Project)
        hosts = project.robot.hosts
        _, _, specs = timed("container specs of every host", lambda: {
            h.name: with_local_build(project, h, host_specs(project, h.name)) for h in hosts})
        assert isinstance(specs, dict)
        _, _, documents = timed("compose documents (spec hashes included)", lambda: {
            name: compose.compose_document(s) for name, s in specs.items()})
        assert isinstance(documents, dict)
        options = {"sort_keys": False, "default_flow_style": False, "width": 120}
        slow, _, _ = timed("YAML text, PyYAML's pure-Python emitter", lambda: [
            yaml.dump(d, Dumper=yaml.SafeDumper, **options) for d in documents.values()])
        if yaml_text.DUMPER is not yaml.SafeDumper:
            timed(f"YAML text, libyaml's emitter ({yaml_text.DUMPER.__name__})", lambda: [
                yaml.dump(d, Dumper=yaml_text.DUMPER, **options) for d in documents.values()])
        fast, _, _ = timed("YAML text, robocore's writer (yaml_text.dump)", lambda: [
            yaml_text.dump(d) for d in documents.values()])
        whole, cpu, _ = timed("write_compose_files (specs, documents, text, files)",
                              lambda: write_compose_files(project))
        print(f"writer {slow / fast:.1f}x PyYAML's; whole {whole:.2f} s = {whole / GOAL_S:.2f} of the "
              f"{GOAL_S:.0f} s goal (CPU {cpu:.2f} s = {cpu / GOAL_S:.2f} of it)")
    record("compose_scale", [
        Figure("YAML text, PyYAML's pure-Python emitter", slow, "s"),
        Figure("YAML text, robocore's writer", fast, "s", ratio=slow / fast, ratio_of="x faster than PyYAML's"),
        Figure("write_compose_files, whole", whole, "s", f"< {GOAL_S:g} s", whole / GOAL_S, "of the goal",
               whole < GOAL_S, f"CPU {cpu:.2f} s"),
    ], goals=[f"the compose files of {args.components:,} components written in under {GOAL_S:g} s"],
        notes=[f"{args.components:,} components on 2 hosts; libyaml: {yaml.__with_libyaml__}"])
    return 0 if whole < GOAL_S else 1


if __name__ == "__main__":
    sys.exit(main())
