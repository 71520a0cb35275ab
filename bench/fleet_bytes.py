"""Bytes to each robot: what a robot pulls for a fleet release v1 -> v2, beside the whole image and rsync.

The template's demo project (wheels base, talker and listener) with a C++ package added to the talker's workspace
(``demo_cpp``: an ament_cmake package of one executable with no ROS library, as ROS 2 from wheels has no rclcpp),
released with ``release --fleet`` to Debian's docker-registry on this machine, four times:

- v1; v2: one line of the talker's Python node changed; v3: one line of ``demo_cpp``'s C++ source changed;
  v4: a new apt package (``less``) for the talker (``stage`` again: a new code-less image under the install tree).

Each release is made twice from the same project: by this checkout (one layer per ROS package) and by the
robocore of ``--baseline`` (default: the commit before the layering, whose ``release --fleet`` put each
component's whole install tree and project files in one layer), from a ``git archive`` of it.

What a robot pulls is computed from the registry's manifests (``docker manifest inspect``, as ``fleet rollout``
does) by Docker Engine's rule: a robot holding the previous release's images (base, talker, listener) downloads
each layer of the new images from the first whose chain it lacks, and the new configurations. No robot's daemon
is asked: the figure is the manifests' compressed sizes, not a measured download. rsync: what ``sync`` moves for
one robot, its own rsync options (``-a -s --delete --copy-unsafe-links``, ``--link-dest`` to the previous
generation) on the two components' install trees of both versions on this machine, delta transfer forced
(``--no-whole-file``, as over ssh): "Total bytes sent" + "received" of ``--stats``. A new apt package is not
something ``sync`` ships (the single robot pulls the new code-less image), so it has no rsync figure.

Goal: a one-line change pulls < 2x what rsync moves and < 1 % of the whole image.

    python bench/fleet_bytes.py [--baseline REV]
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from harness import Figure, record, robocore

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "integration"))
sys.path.insert(0, str(ROOT))

from local_registry import serve_registry  # noqa: E402

from robocore.adapters.docker_manifest import image_layers  # noqa: E402
from robocore.plan.pull_bytes import ImageLayers, human, pull_bytes  # noqa: E402

#: The commit whose release --fleet made one layer per component (the last before the layering).
BASELINE = "6c48fd4"
CPP_XML = """<?xml version="1.0"?>
<package format="3">
  <name>demo_cpp</name>
  <version>0.1.0</version>
  <description>A C++ program with no ROS library.</description>
  <maintainer email="dev@example.com">robot developer</maintainer>
  <license>Apache-2.0</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <export><build_type>ament_cmake</build_type></export>
</package>
"""
CPP_CMAKE = """cmake_minimum_required(VERSION 3.8)
project(demo_cpp CXX)
find_package(ament_cmake REQUIRED)
add_executable(hello src/hello.cpp)
install(TARGETS hello DESTINATION lib/${PROJECT_NAME})
ament_package()
"""
CPP_SOURCE = """#include <iostream>
#include <string>
#include <vector>

int main() {
  std::vector<std::string> words{"hello", "from", "the", "robot"};
  for (const auto& word : words) std::cout << word << ' ';
  std::cout << "v1" << std::endl;
  return 0;
}
"""
COMPONENTS = ("talker", "listener")


def baseline_tree(rev: str, parent: Path) -> Path:
    """robocore as of ``rev`` (``git archive``), to run with PYTHONPATH."""
    out = parent / "baseline"
    out.mkdir()
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev, "--", "robocore"], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(out)], input=archive, check=True)
    return out


def release(project: Path, tag: str, baseline: Path | None) -> dict[str, str]:
    """``release --fleet --tag TAG`` (by this checkout, or by the baseline's robocore); the images by digest."""
    import json

    # PYTHONSAFEPATH: `python -m` would put the working folder (this checkout) before PYTHONPATH
    env = {**os.environ, "PYTHONPATH": str(baseline if baseline else ROOT), "PYTHONSAFEPATH": "1"}
    robocore(project, "release", "--fleet", "--tag", tag, env=env)
    data = json.loads((project / ".robocore" / "releases" / f"{tag}.json").read_text())
    return {"base": data["base"]["amd64"], **{c: data["components"][c]["amd64"] for c in COMPONENTS}}


def snapshot(project: Path, into: Path) -> Path:
    """The components' install trees as ``sync`` ships them, copied to ``into``."""
    for component in COMPONENTS:
        shutil.copytree(project / ".robocore" / "build" / component / "install", into / component, symlinks=True)
    return into


def rsync_bytes(old: Path, new: Path, scratch: Path) -> int:
    """Bytes rsync moves to bring a robot's generation ``old`` to ``new`` (sync's options, delta forced)."""
    current = scratch / "current"
    shutil.rmtree(scratch, ignore_errors=True)
    shutil.copytree(old, current, symlinks=True)
    done = subprocess.run(["rsync", "-a", "-s", "--delete", "--copy-unsafe-links", "--stats", "--no-whole-file",
                           f"--link-dest={current}/", "--", f"{new}/", f"{scratch}/next/"],
                          check=True, capture_output=True, text=True)

    def stat(name: str) -> int:
        found = re.search(rf"^{name}: ([\d,]+)", done.stdout, re.MULTILINE)
        assert found, done.stdout
        return int(found.group(1).replace(",", ""))

    return stat("Total bytes sent") + stat("Total bytes received")


def describe(image: ImageLayers) -> str:
    """The layers above the base's two and the configuration: digest prefix and kB."""
    return " ".join(f"{digest[7:13]}:{size / 1000:.1f}" for digest, size in image.layers[2:]) + \
        f" config {image.config[1] / 1000:.1f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", default=BASELINE, help="the robocore commit of one layer per component")
    args = parser.parse_args()
    parent = Path(tempfile.mkdtemp(prefix="robocore-bench-bytes-"))
    os.environ["PYTHONPATH"] = str(ROOT)  # this checkout's robocore for every step but the baseline's releases
    demo = parent / "robocore-bench-bytes"  # its own images: the C++ package gives its talker a compiler
    robocore(None, "init", str(demo), "--defaults", "--base", "wheels")
    cpp = demo / "components" / "talker" / "src" / "demo_cpp"
    (cpp / "src").mkdir(parents=True)
    (cpp / "package.xml").write_text(CPP_XML)
    (cpp / "CMakeLists.txt").write_text(CPP_CMAKE)
    (cpp / "src" / "hello.cpp").write_text(CPP_SOURCE)
    for step in ("prepare-base", "stage", "build"):
        robocore(demo, step, "--quiet")
    old = baseline_tree(args.baseline, parent)
    manifests: dict[str, ImageLayers] = {}

    def layers(ref: str) -> ImageLayers:
        if ref not in manifests:
            manifests[ref] = image_layers(ref, insecure=True)
        return manifests[ref]

    talker_py = demo / "components" / "talker" / "src" / "demo_talker" / "demo_talker" / "talker.py"
    steps = [
        ("one-line Python change", lambda: talker_py.write_text(
            talker_py.read_text().replace('print(f"Publishing: {msg.data}"', 'print(f"Publishing now: {msg.data}"')),
         ("build",)),
        ("one-line C++ change", lambda: (cpp / "src" / "hello.cpp").write_text(CPP_SOURCE.replace('"v1"', '"v2"')),
         ("build",)),
        ("new apt package", lambda: (demo / "robot.yaml").write_text((demo / "robot.yaml").read_text().replace(
            "    entrypoint: ros2 run demo_talker talker\n",
            "    entrypoint: ros2 run demo_talker talker\n    apt_packages: [less]\n")), ("stage", "build")),
    ]
    (parent / "registry").mkdir()
    figures: list[Figure] = []
    table: list[tuple[str, ...]] = []
    with serve_registry(None, parent / "registry") as registry:
        (demo / "fleet.yaml").write_text(f"manager: {{ip: 10.200.0.1}}\nregistry: {registry}\nrobots:\n"
                                         "  - {name: r1, hosts: {devmachine: {ip: 10.200.1.1}}}\n")
        new, before = release(demo, "l1", None), release(demo, "o1", old)
        trees = snapshot(demo, parent / "trees-1")
        for index, (what, change, commands) in enumerate(steps, start=2):
            change()
            for command in commands:
                robocore(demo, command, "--quiet")
            after_new, after_before = release(demo, f"l{index}", None), release(demo, f"o{index}", old)
            next_trees = snapshot(demo, parent / f"trees-{index}")
            for name, was, now in (("per package", new, after_new), ("per component", before, after_before)):
                print(f"{what}, {name}: talker layers (kB) {describe(layers(was['talker']))} -> "
                      f"{describe(layers(now['talker']))}", flush=True)
            whole = layers(after_new["talker"]).size
            layered = pull_bytes([layers(r) for r in after_new.values()], [layers(r) for r in new.values()])
            one = pull_bytes([layers(r) for r in after_before.values()], [layers(r) for r in before.values()])
            rsync = rsync_bytes(trees, next_trees, parent / "rsync") if what != "new apt package" else None
            cost = layered / whole
            ok = rsync is not None and layered < 2 * rsync and cost < 0.01
            figures += [
                Figure(f"{what}: whole talker image", whole, "bytes"),
                Figure(f"{what}: one layer per component (before)", one, "bytes",
                       ratio=one / rsync if rsync else one / whole, ratio_of="x rsync" if rsync else "of the image"),
                Figure(f"{what}: one layer per ROS package (now)", layered, "bytes",
                       goal="< 2x rsync, < 1 % of the image" if rsync is not None else None,
                       ratio=layered / rsync if rsync else None, ratio_of="x rsync" if rsync else "",
                       met=ok if rsync is not None else None,
                       detail=f"{cost:.3%} of the image; {one / layered:.1f}x less than one layer per component"
                       + ("" if rsync else "; the new package is in the code-less image's apt layer (with the "
                          "compiler), below the install tree: every layer from it up comes again")),
            ]
            if rsync is not None:
                figures.append(Figure(f"{what}: rsync (sync) of the install trees", rsync, "bytes"))
            table.append((what, human(whole), human(one), human(layered), human(rsync) if rsync is not None else "-",
                          f"{layered / rsync:.2f}x" if rsync else "-", f"{cost:.3%}"))
            new, before, trees = after_new, after_before, next_trees
    head = ("v1 -> v2", "whole image", "one layer/component", "one layer/package", "rsync (sync)",
            "package/rsync", "package/image")
    widths = [max(len(row[i]) for row in [head, *table]) for i in range(len(head))]
    for row in [head, *table]:
        print("  ".join(cell.ljust(width) for cell, width in zip(row, widths, strict=True)), flush=True)
    record("fleet_bytes", figures, goals=["a one-line change pulls < 2x what rsync moves and < 1 % of the image"],
           notes=[f"baseline (one layer per component): robocore {args.baseline}",
                  "pulled bytes computed from the registry's manifests by Docker Engine's chain rule, per robot "
                  "holding the previous release (base, talker, listener); rsync: sync's options on this machine"])
    remove_tags(registry)
    shutil.rmtree(parent, ignore_errors=True)


def remove_tags(registry: str) -> None:
    """This machine's tags under ``registry`` (the releases pushed), as the integration suites remove theirs."""
    import docker

    client = docker.from_env()
    for found in client.images.list():
        for tag in found.tags:
            if tag.startswith(f"{registry}/"):
                client.images.remove(tag)
    client.close()


if __name__ == "__main__":
    main()
