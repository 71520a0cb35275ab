"""The Kubernetes export at fleet scale: 1000 robots x 8 components, exported, rendered and checked --strict.

One model (robot.yaml: jazzy, two hosts of which one arm64, 8 components, one Fast DDS discovery server) and a
fleet of N robots in three waves (a canary, 10 %, the rest), each with a label. Steps, each timed:

1. **export**: ``robocore export kubernetes`` of the fleet into a new folder (planning and writing every file);
2. **render**: ``kubectl kustomize`` of every robot's overlay, as each robot's controller renders its own
   folder, no network. kustomize's cost grows with the square of the objects of one render (the root
   kustomization of 1000 robots, 12,000 objects, did not finish in 15 min here; 100 robots took 10 s of CPU,
   200 took 42 s), and each ``kubectl`` costs ~0.07 s of CPU to start, so the overlays are rendered in batches
   of :data:`BATCH` robots (a kustomization listing them, in a scratch folder), one batch per core at a time.
   Every overlay reads its model's base again (kustomize keeps nothing between two resources): about half of a
   robot's time is that, the rest its transformers (namespace, labels and node pinning, images). At Go's default
   ``GOGC=100`` a third of kustomize's CPU is its garbage collector, and more the bigger the batch (per robot, in
   batches of 10, 20, 40: 80, 104, 123 ms); with ``GOGC=400`` (:data:`GOGC`, ~90-150 MB per render) it is
   56-68 ms per robot for any batch of 5 to 40 robots. ``--gogc 100`` measures the default;
3. **strict, base once**: ``kubernetes-validate --strict`` of every object of one robot's overlay, for
   Kubernetes 1.30 and the newest bundled (each model's base is validated once);
4. **overlays change only ...**: every object of every robot compared with the same object of the first robot:
   the only differences allowed are the namespace, the robot's labels, the images and the robot's node pinning.
   With step 3, every rendered object of the fleet is as valid as the checked ones;
5. **a change to one robot, on Fleet**: the exported fleet.yaml through the model of Fleet's partition code
   (tests/fleet_model.py). Fleet's deployment ID hashes the whole bundle, so one robot's change is a new
   deployment for every robot; the figure is how many robots then take a turn, one at a time (the controller
   passes until every robot is on it), and the model's own time.

Between 2 and 3 the rendered text is parsed (timed on its own line, counted with steps 3 and 4: it is the
checks' input, not kustomize's work).

Goals: export + render < 90 s; parse + steps 3 + 4 < 30 s (the alternative to validating all of it, < 5 min). Each
step prints its wall-clock seconds and the CPU seconds it used (this process and its children), and the ratio of
its wall-clock time to its goal (< 1 meets it): on a shared machine the CPU figure is the one that says what the
step costs.

``--baseline DIR`` (a folder holding another robocore package, e.g. ``git archive main robocore | tar -x -C DIR``)
exports the fleet with that robocore too, just before, prints its row beside and checks both exports byte-identical.

    python bench/k8s_export.py [--robots 1000] [--keep DIR] [--gogc 400] [--baseline DIR]
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import kubernetes_validate
import yaml
from harness import Figure, record

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from fleet_model import Cluster, roll_out, targets
from k8s_checks import VERSIONS

COMPONENTS = 8
#: Robots per kustomize render: each render costs a start-up plus the square of its objects; 20 is cheapest here.
BATCH = 20
#: Go's GOGC for kustomize (its collector runs when the heap grows by this percentage; default 100).
GOGC = 400
#: Renders at a time: one per core.
WORKERS = os.cpu_count() or 2
ROBOT_YAML = """\
ros_distro: jazzy
registry: 10.0.0.2:5000
hosts:
  - {{name: main, ip: 10.0.0.10}}
  - {{name: jetson, ip: 10.0.0.11, arch: arm64}}
components:
{components}"""
#: Paths (from an object's top) whose values may differ between two robots' copies of one object.
ALLOWED = (("metadata", "namespace"), ("metadata", "labels"), ("spec", "template", "metadata", "labels"),
           ("spec", "template", "spec", "nodeSelector", "robocore.dev/robot"))


def project(root: Path, robots: int) -> Path:
    """A project folder with robot.yaml (8 components over two hosts) and a fleet of ``robots`` robots."""
    root.mkdir(parents=True)
    components = "".join(f"  - {{name: c{i}, folder: c{i}, runs_on: {'jetson' if i % 4 == 3 else 'main'}, "
                         f"entrypoint: ros2 run pkg{i} node{i}}}\n" for i in range(COMPONENTS))
    (root / "robot.yaml").write_text(ROBOT_YAML.format(components=components))
    for i in range(COMPONENTS):
        (root / f"c{i}").mkdir()
    lines = ["engine: kubernetes\nrobots:\n"]
    for n in range(robots):
        lines.append(f"  - name: r{n}\n    labels: {{site: s{n % 7}}}\n    hosts:\n"
                     f"      main: {{ip: 10.{n // 256 % 256}.{n % 256}.10}}\n"
                     f"      jetson: {{ip: 10.{n // 256 % 256}.{n % 256}.11}}\n")
    lines.append("rollout:\n  waves:\n    - {name: canary, robots: [r0]}\n    - {name: early, percent: 10}\n"
                 "    - {name: rest}\n")
    (root / "fleet.yaml").write_text("".join(lines))
    return root


def differences(a: Any, b: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Paths where ``a`` and ``b`` differ (lists compared item by item)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return [p for k in sorted(set(a) | set(b), key=str)
                for p in (differences(a.get(k), b.get(k), (*path, k)) if k in a and k in b else [(*path, k)])]
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return [p for i, (x, y) in enumerate(zip(a, b, strict=True)) for p in differences(x, y, (*path, i))]
    return [] if a == b else [path]


def allowed(path: tuple[Any, ...], kind: str) -> bool:
    """A difference the overlays may make: namespace, labels, an image, the robot's node pinning (and the
    Namespace object's own name, and the namespace of the RoleBinding's service account)."""
    if kind == "Namespace" and path == ("metadata", "name"):
        return True
    if kind == "RoleBinding" and path[:1] == ("subjects",) and path[-1] == "namespace":
        return True  # the health Job's service account, in the robot's namespace
    if any(path[:len(prefix)] == prefix for prefix in ALLOWED):
        return True
    return len(path) >= 2 and path[-1] == "image" and any(p in ("containers", "initContainers") for p in path)


def by_robot_names(by_robot: dict[str, list[dict[str, Any]]]) -> list[str]:
    """The robots' names, from their namespaces (``robot-<name>``), in wave order (r0 the canary, then by number)."""
    return sorted((ns.removeprefix("robot-") for ns in by_robot), key=lambda name: int(name[1:]))


def cpu() -> float:
    """CPU seconds used so far by this process and the children it waited for."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def render_all(export: Path, scratch: Path, gogc: int) -> list[str]:
    """The YAML text of every robot's overlay, rendered :data:`BATCH` robots at a time, :data:`WORKERS` at once,
    kustomize with Go's ``GOGC=gogc`` (a failed render raises)."""
    robots = sorted(p.name for p in (export / "robots").iterdir())
    batches = []
    for start in range(0, len(robots), BATCH):
        folder = scratch / f"b{start}"
        folder.mkdir(parents=True)
        names = "".join(f"- {os.path.relpath(export / 'robots' / r, folder)}\n" for r in robots[start:start + BATCH])
        (folder / "kustomization.yaml").write_text(f"resources:\n{names}")
        batches.append(folder)
    prefix = ["unshare", "-n"] if shutil.which("unshare") else []
    env = {**os.environ, "GOGC": str(gogc)}

    def render(folder: Path) -> str:
        argv = [*prefix, "kubectl", "kustomize", str(folder)]
        return subprocess.run(argv, capture_output=True, text=True, check=True, env=env).stdout

    with ThreadPoolExecutor(WORKERS) as pool:
        return list(pool.map(render, batches))


def export(root: Path, out: Path, env: dict[str, str] | None) -> tuple[float, float]:
    """Wall-clock and CPU seconds of ``robocore export kubernetes`` of ``root`` into ``out`` (``env``: another
    robocore first on PYTHONPATH); a failed export stops the bench."""
    started, used = time.monotonic(), cpu()
    done = subprocess.run([sys.executable, "-m", "robocore", "-p", str(root), "export", "kubernetes", str(out),
                           "--tag", "v1"], capture_output=True, text=True, env=env)
    if done.returncode != 0:
        raise SystemExit(f"export failed: {done.stderr}")
    return time.monotonic() - started, cpu() - used


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=1000)
    parser.add_argument("--keep", type=Path, help="work in this folder and keep it")
    parser.add_argument("--gogc", type=int, default=GOGC, help=f"Go's GOGC for kustomize (default {GOGC}; Go's "
                        "own: 100)")
    parser.add_argument("--baseline", type=Path, help="a folder holding another robocore package: its export too")
    args = parser.parse_args()
    work = args.keep or Path(tempfile.mkdtemp(prefix="robocore-k8s-bench-"))
    rows: list[tuple[str, float, float, str, float | None]] = []
    try:
        root = project(work / "fleetbot", args.robots)
        out = work / "export"
        if args.baseline is not None:
            old = work / "export-baseline"
            seconds, used_s = export(root, old, {**os.environ, "PYTHONPATH": str(args.baseline.resolve())})
            rows.append(("export, baseline robocore (new process)", seconds, used_s, "", None))
        export_s, export_c = export(root, out, None)
        files = sum(1 for p in out.rglob("*") if p.is_file())
        if args.baseline is not None:
            differ = subprocess.run(["diff", "-rq", str(old), str(out)], capture_output=True, text=True)
            if differ.returncode != 0:
                raise SystemExit(f"the export differs from the baseline's:\n{differ.stdout[:3000]}")
            files_text = f"{files} files, = baseline"
        else:
            files_text = f"{files} files"
        rows.append(("export (new process)", export_s, export_c, files_text, None))
        started, used = time.monotonic(), cpu()
        texts = render_all(out, work / "batches", args.gogc)
        render_s, render_c = time.monotonic() - started, cpu() - used
        rows.append((f"render (kubectl kustomize, {BATCH} robots a render)", render_s, render_c,
                     f"{sum(len(t) for t in texts) >> 20} MB YAML", None))
        rows.append(("export + render", export_s + render_s, export_c + render_c, "", 90.0))
        started, used = time.monotonic(), cpu()
        docs = [d for text in texts for d in yaml.load_all(text, Loader=yaml.CSafeLoader) if d]
        parse_s, parse_c = time.monotonic() - started, cpu() - used
        rows.append(("parse the rendered YAML (for the checks)", parse_s, parse_c, f"{len(docs)} objects", None))
        by_robot: dict[str, list[dict[str, Any]]] = {}
        for doc in docs:
            ns = doc["metadata"].get("namespace", doc["metadata"]["name"])
            by_robot.setdefault(ns, []).append(doc)
        assert len(by_robot) == args.robots, f"{len(by_robot)} robots rendered, not {args.robots}"
        first, *others = by_robot.values()
        started, used = time.monotonic(), cpu()
        for doc in first:
            for version in VERSIONS:
                kubernetes_validate.validate(doc, version, strict=True)
        strict_s, strict_c = time.monotonic() - started, cpu() - used
        rows.append((f"strict, one robot ({', '.join(VERSIONS)})", strict_s, strict_c, f"{len(first)} objects",
                     None))
        started, used = time.monotonic(), cpu()
        reference = {(d["kind"], d["metadata"]["name"].rsplit("-", 1)[0] if d["kind"] in ("ConfigMap", "Namespace")
                      else d["metadata"]["name"]): d for d in first}
        compared = 0
        for objects in others:
            assert len(objects) == len(first), "a robot's overlay has other objects than the first robot's"
            for doc in objects:
                key = (doc["kind"], doc["metadata"]["name"].rsplit("-", 1)[0]
                       if doc["kind"] in ("ConfigMap", "Namespace") else doc["metadata"]["name"])
                bad = [p for p in differences(reference[key], doc) if not allowed(p, doc["kind"])]
                assert not bad, f"{key} differs from the first robot's beyond the overlay's fields: {bad[:3]}"
                compared += 1
        proof_s, proof_c = time.monotonic() - started, cpu() - used
        rows.append(("overlays change only ns/labels/images/pinning", proof_s, proof_c, f"{compared} objects", None))
        rows.append(("parse + strict once + proof", parse_s + strict_s + proof_s, parse_c + strict_c + proof_c, "",
                     30.0))
        started, used = time.monotonic(), cpu()
        fleet_yaml = yaml.safe_load((out / "fleet.yaml").read_text())
        clusters = targets(fleet_yaml, [Cluster(r, {"robocore.dev/robot": r}) for r in by_robot_names(by_robot)])
        roll_out(fleet_yaml, clusters, "v1", lambda cluster, deployment: True)
        turns = roll_out(fleet_yaml, clusters, "v1+r0", lambda cluster, deployment: True, passes=10 * args.robots)
        turns_s, turns_c = time.monotonic() - started, cpu() - used
        assert all(len(step) == 1 for step in turns) and len(turns) == args.robots, "not one robot a turn"
        rows.append((f"Fleet: one robot changed, {len(turns)} turns", turns_s, turns_c,
                     f"{len(turns)} robots", None))
    finally:
        if args.keep is None:
            shutil.rmtree(work, ignore_errors=True)
    print(f"robocore export kubernetes: {args.robots} robots x {COMPONENTS} components, {WORKERS} renders at a time, "
          f"GOGC={args.gogc}, load average {os.getloadavg()[0]:.1f} at the end")
    print(f"{'step':48} {'wall s':>8} {'CPU s':>8}  {'what':>16}  {'goal':>8} {'wall/goal':>9}")
    for name, seconds, used_s, what, goal in rows:
        target = f"< {goal:.0f} s" if goal else ""
        ratio = f"{seconds / goal:9.2f}" if goal else ""
        print(f"{name:48} {seconds:8.1f} {used_s:8.1f}  {what:>16}  {target:>8} {ratio}")
    record("k8s_export", [Figure(name, seconds, "s", f"< {goal:.0f} s" if goal else None,
                                 seconds / goal if goal else None, "wall / goal", seconds < goal if goal else None,
                                 f"CPU {used_s:.1f} s" + (f"; {what}" if what else ""))
                          for name, seconds, used_s, what, goal in rows],
           goals=["export + render < 90 s", "parse + strict validation of one robot + the overlay proof < 30 s"],
           notes=[f"{args.robots} robots x {COMPONENTS} components, {WORKERS} renders at a time, GOGC={args.gogc}"])


if __name__ == "__main__":
    main()
