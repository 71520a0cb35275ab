"""Benchmark of prepare-base, stage and build on the template project (wheels base).

Prints, side by side in one run:
- the base built from scratch (Docker's layer cache bypassed), the first time on a machine;
- cold prepare-base + stage + build of a new project (no project image; Docker's layer cache
  may already hold identical layers, as on a developer's machine);
- no-op stage (goal < 2 s) and no-op build (goal < 3 s);
- a one-line edit to the talker's Python until rebuilt artifacts (goal < 5 s), against the same
  edit through a plain `docker build` of an image with the code inside, and the ratio;
- image sizes (wheels base <= 550 MB).

Usage: python bench/images.py [--skip-scratch]   (needs Docker; removes only its own images)
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import docker
from harness import Figure, record, robocore

NAME = "robocore-bench-img"
PLAIN = f"{NAME}-plain-docker:latest"


def timed(project: Path | None, *args: str) -> float:
    """Seconds of ``robocore [-p PROJECT] ARGS`` (a failure stops the bench)."""
    start = time.perf_counter()
    robocore(project, *args)
    return time.perf_counter() - start


def goal(value: float, limit: float, unit: str) -> str:
    return f"goal < {limit:g} {unit} " + ("ok" if value < limit else "MISSED")


def remove_own_images(client: docker.DockerClient) -> None:
    for image in client.images.list():
        if any(tag.startswith(f"{NAME}-") for tag in image.tags):
            for tag in image.tags:
                if tag.startswith(f"{NAME}-"):
                    client.images.remove(tag, force=True, noprune=False)


def talker_source(project: Path) -> Path:
    for path in sorted((project / "components").rglob("*.py")):
        if path.name != "setup.py" and "talker" in path.name:
            return path
    sys.exit("no talker source in the template project")


def scratch_base(project: Path) -> float:
    """The project's base Dockerfile built through robocore's builder with Docker's cache off."""
    from robocore.adapters.docker_hosts import local_client
    from robocore.adapters.image_builder import build_image
    from robocore.commands.prepare_base import plan_base
    from robocore.commands.support.machine import native_arch
    from robocore.plan.dockerfiles import ImagePlan
    from robocore.project import Project

    proj = Project.load(project)
    client = local_client(timeout=3600)
    planned = plan_base(proj, client, native_arch())
    plan = planned.plan
    scratch = ImagePlan(role=plan.role, name=f"{NAME}-scratch", tag="latest", arch=plan.arch,
                        dockerfile=plan.dockerfile, parent=plan.parent, context=plan.context)
    start = time.perf_counter()
    build_image(client, scratch, planned.files, labels={}, native_arch=native_arch(), nocache=True)
    elapsed = time.perf_counter() - start
    client.images.remove(scratch.ref, force=True)
    return elapsed


def plain_docker_edit(project: Path, base: str, source: Path) -> tuple[float, float]:
    """Build an image with the talker's code inside (first build, then after a one-line edit)."""
    ctx = project / "components" / "talker"
    dockerfile = textwrap.dedent(f"""\
        FROM {base}
        COPY . /ws
        RUN . /opt/ros/$ROS_DISTRO/setup.bash && cd /ws && colcon build --event-handlers console_direct-
        """)
    (ctx / "Dockerfile.bench").write_text(dockerfile)
    argv = ["docker", "build", "-q", "-f", str(ctx / "Dockerfile.bench"), "-t", PLAIN, str(ctx)]
    try:
        start = time.perf_counter()
        subprocess.run(argv, check=True, capture_output=True)
        first = time.perf_counter() - start
        source.write_text(source.read_text() + "\n# plain docker edit\n")
        start = time.perf_counter()
        subprocess.run(argv, check=True, capture_output=True)
        edit = time.perf_counter() - start
    finally:
        (ctx / "Dockerfile.bench").unlink()
    return first, edit


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--skip-scratch", action="store_true", help="skip the base build without layer cache")
    args = parser.parse_args()
    client = docker.from_env(timeout=3600)
    parent = Path(tempfile.mkdtemp(prefix="robocore-bench-"))
    project = parent / NAME
    rows: list[tuple[str, str, str]] = []
    figures: list[Figure] = []
    try:
        remove_own_images(client)
        timed(None, "init", str(project), "--defaults", "--base", "wheels")
        from robocore.plan import naming
        from robocore.project import Project

        proj = Project.load(project)
        base = f"{naming.base_image(proj.robot, proj.name)}:latest"
        if not args.skip_scratch:
            scratch = scratch_base(project)
            rows.append(("base from scratch (no layer cache)", f"{scratch:7.1f} s", ""))
            figures.append(Figure("base from scratch (no layer cache)", scratch, "s"))
        t_base = timed(project, "prepare-base", "--quiet")
        t_stage = timed(project, "stage", "--quiet")
        t_build = timed(project, "build", "--quiet")
        rows.append(("cold project: prepare-base", f"{t_base:7.1f} s", ""))
        rows.append(("cold project: stage", f"{t_stage:7.1f} s", ""))
        rows.append(("cold project: build", f"{t_build:7.1f} s", ""))
        rows.append(("cold project: total", f"{t_base + t_stage + t_build:7.1f} s", ""))
        figures += [Figure("cold project: prepare-base", t_base, "s"), Figure("cold project: stage", t_stage, "s"),
                    Figure("cold project: build", t_build, "s"),
                    Figure("cold project: total", t_base + t_stage + t_build, "s")]
        noop_stage = min(timed(project, "stage", "--quiet") for _ in range(3))
        noop_build = min(timed(project, "build", "--quiet") for _ in range(3))
        rows.append(("no-op stage (best of 3)", f"{noop_stage:7.2f} s", goal(noop_stage, 2, "s")))
        rows.append(("no-op build (best of 3)", f"{noop_build:7.2f} s", goal(noop_build, 3, "s")))
        figures += [Figure("no-op stage (best of 3)", noop_stage, "s", "< 2 s", noop_stage / 2, "of the goal",
                           noop_stage < 2),
                    Figure("no-op build (best of 3)", noop_build, "s", "< 3 s", noop_build / 3, "of the goal",
                           noop_build < 3)]

        source = talker_source(project)
        edits = []
        for i in range(3):
            source.write_text(source.read_text() + f"\n# bench edit {i}\n")
            edits.append(timed(project, "build", "--quiet"))
            installed = list((proj.build_dir("talker") / "install").rglob(source.name))
            assert any(f"# bench edit {i}" in p.read_text() for p in installed), "edit not in the install tree"
        edit = min(edits)
        rows.append(("one-line edit -> rebuilt install tree (best of 3)", f"{edit:7.2f} s", goal(edit, 5, "s")))
        first, plain = plain_docker_edit(project, base, source)
        rows.append(("plain docker build, code in image: first build", f"{first:7.2f} s", ""))
        rows.append(("plain docker build, code in image: one-line edit", f"{plain:7.2f} s",
                     f"robocore is {plain / edit:.1f}x faster"))
        figures += [Figure("one-line edit -> rebuilt install tree (best of 3)", edit, "s", "< 5 s", edit / 5,
                           "of the goal", edit < 5),
                    Figure("plain docker build, code in image: first build", first, "s"),
                    Figure("plain docker build, code in image: one-line edit", plain, "s", ratio=plain / edit,
                           ratio_of="x robocore's edit")]
        for comp in ("base", "talker", "listener"):
            ref = base if comp == "base" else f"{naming.component_image(proj.robot, proj.name, comp)}:latest"
            size = client.images.get(ref).attrs["Size"] / 1e6
            note = goal(size, 550, "MB") if comp == "base" else "shares the base layers"
            rows.append((f"image size: {comp}", f"{size:7.0f} MB", note))
            figures.append(Figure(f"image size: {comp}", size, "MB", "<= 550 MB" if comp == "base" else None,
                                  met=size <= 550 if comp == "base" else None,
                                  detail="" if comp == "base" else "shares the base layers"))
    finally:
        remove_own_images(client)
        shutil.rmtree(parent, ignore_errors=True)
    width = max(len(r[0]) for r in rows)
    print(f"{'measure':<{width}}  {'value':>10}  note")
    for what, value, note in rows:
        print(f"{what:<{width}}  {value:>10}  {note}")
    record("images", figures, goals=["no-op stage < 2 s", "no-op build < 3 s", "one-line edit to rebuilt artifacts "
                                     "< 5 s", "wheels base image <= 550 MB"],
           notes=["the template project (wheels base); the cold project may reuse Docker's layer cache"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
