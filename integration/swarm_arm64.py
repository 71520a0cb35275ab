"""The arm64 robot of the Swarm fleet suite: a noetic project whose only host is arm64, run through qemu.

ROS 2 has no aarch64 wheels here, so the fleet's arm64 robot runs ROS 1: the template's noetic project on the
debian base (``robocore-it-arm64``, the arm64 suites' project, whose arm64 root, base, talker and listener images
:mod:`arm64_project` makes in the background) as a fleet model of one arm64 host: the ROS master, the roscpp talker
and the rospy listener all on it. Its robot (``a1``) is a DinD robot host of the same swarm as the ROS 2 fleets,
labelled arm64 by ``fleet join``; its dockerd runs the arm64 containers through the kernel's qemu-aarch64 entry as
an arm64 robot's daemon runs them natively.

Its releases are made by robocore itself, under emulation (``build`` of the C++ talker, ``release --fleet``), one
after the other in the background while the ROS 2 fleets join and roll out (:class:`ArmReleases`):

- v1: the project as the template makes it;
- v2: the talker says "hello v2" (its header changed, the talker rebuilt for arm64);
- v3: the talker's container runs but is no ROS node (its binary a shell script that sleeps): the ROS 1 gate's
  negative control.
"""

from __future__ import annotations

import json
import shutil
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import yaml
from arm64_project import NAME, built_fleet_project, init_fleet_project

#: The arm64 fleet's project (the arm64 suites' project name, so their images are its images) and its robot.
ARM = NAME
ROBOT = "a1"
#: The greeting's header in the talker's workspace (what v2 changes).
GREETING_H = "components/talker/src/demo_talker/include/demo_talker/greeting.h"
#: Seconds a robot's gate may take: starting everything under emulation.
ROBOT_TIMEOUT = 240
#: The robot timeout of the negative control: its probe waits this long (less the time to start) for a node that
#: never comes.
CONTROL_TIMEOUT = 60
#: A placeholder address (TEST-NET-1) until the robot host is up: building and releasing contact no host.
PLACEHOLDER = "192.0.2.10"


def write_fleet(root: Path, manager: str, robot_ip: str, registry: str, robot_timeout: int = ROBOT_TIMEOUT) -> None:
    """The arm64 fleet's fleet.yaml: one robot of one host, gated by the ROS 1 probe (3 containers running, the
    talker and listener nodes in its master's graph, /chatter heard)."""
    fleet = {
        "engine": "swarm",
        "manager": {"ip": manager, "user": "root"},
        "registry": registry,
        "robots": [{"name": ROBOT, "hosts": {"robot": {"ip": robot_ip}}}],
        "rollout": {
            "health": {"running": 3, "nodes": ["/talker", "/listener"], "heard": ["/chatter"]},
            # the graph's bound as long as the robot's: under emulation its nodes take long to start
            "timeouts": {"robot": robot_timeout, "heard": robot_timeout, "wave": 600},
        },
    }
    (root / "fleet.yaml").write_text(yaml.safe_dump(fleet, sort_keys=False))


def set_robot_timeout(root: Path, seconds: int) -> str:
    """Set the fleet file's robot timeout; its previous text, to write back."""
    fleet_file = root / "fleet.yaml"
    original = fleet_file.read_text()
    data = yaml.safe_load(original)
    data["rollout"]["timeouts"]["robot"] = seconds
    fleet_file.write_text(yaml.safe_dump(data, sort_keys=False))
    return original


def record(root: Path, version: str) -> dict[str, Any]:
    """The release record of ``version``."""
    data: dict[str, Any] = json.loads((root / ".robocore" / "releases" / f"{version}.json").read_text())
    return data


class ArmReleases:
    """v1, v2 and v3 of the arm64 fleet, made one after the other on ``pool`` (one worker: they change the same
    project folder) from the moment this is made; :meth:`ready` waits for one. ``run`` is the suites'
    ``run_robocore`` (root, *args); ``base_pushed`` waits for the early push of the arm64 base (:func:`pushed_early`),
    which v1's release must not race: the registry answers two pushes of one layer at once with a 500."""

    def __init__(self, root: Path, run: Callable[..., Any], pool: ThreadPoolExecutor, timings: dict[str, float],
                 base_pushed: Callable[[], object]) -> None:
        self.root, self._run, self.timings, self._base_pushed = root, run, timings, base_pushed
        self._made = {"v1": pool.submit(self._v1)}
        self._made["v2"] = pool.submit(self._v2)
        self._made["v3"] = pool.submit(self._v3)

    def ready(self, version: str) -> None:
        """Wait until ``version`` is released (its record written); raises what making it raised."""
        self._made[version].result()

    def _timed(self, step: str, *args: str, action: Callable[[], object] | None = None) -> None:
        """``robocore ARGS`` on the project (or ``action``), its seconds kept as ``step``'s."""
        started = time.monotonic()
        if action is None:
            self._run(self.root, *args)
        else:
            action()
        self.timings[step] = round(time.monotonic() - started, 1)

    def _v1(self) -> None:
        for step in ("prepare-base", "stage", "build"):
            self._timed(step, step, "--quiet")
        self._timed("base pushed early (waited for)", action=self._base_pushed)
        self._timed("release v1", "release", "--fleet", "--tag", "v1")

    def _v2(self) -> None:
        header = self.root / GREETING_H
        header.write_text(header.read_text().replace('"hello from talker #"', '"hello v2 from talker #"'))
        self._timed("build talker v2", "build", "--component", "talker", "--quiet")
        self._timed("release v2", "release", "--fleet", "--tag", "v2")

    def _v3(self) -> None:
        install = self.root / ".robocore" / "build" / "talker" / "install"
        [binary] = [p for p in install.rglob("talker") if p.is_file() and not p.is_symlink()]
        saved = binary.with_name("talker.arm64")
        shutil.move(binary, saved)
        try:  # the talker's container runs (a shell that sleeps), but no /talker node, nothing on /chatter
            binary.write_text("#!/bin/sh\nexec sleep 100000\n")
            binary.chmod(0o755)
            self._timed("release v3", "release", "--fleet", "--tag", "v3")
        finally:
            binary.unlink(missing_ok=True)
            shutil.move(saved, binary)


def make_arm_project(parent: Path, registry: str) -> Path:
    """The arm64 fleet's project under ``parent``: a copy of the one the background script built (its install
    trees and ccache: the suite's ``build`` then compiles nothing it need not), else ``robocore init`` anew;
    placeholder addresses in its fleet file until the hosts are up (:func:`write_fleet` again then)."""
    root = parent / NAME
    built = built_fleet_project()
    if built is not None:
        shutil.copytree(built, root, symlinks=True)
    else:
        init_fleet_project(root, PLACEHOLDER)
    write_fleet(root, "192.0.2.2", PLACEHOLDER, registry)
    return root


def pushed_early(docker_client: Any, image: str, ref: str) -> None:
    """Push ``image`` (the arm64 base the background made) as ``ref`` while the project is built, so that
    ``release --fleet`` finds its layers in the registry already; nothing when it is not there (the release then
    pushes it itself)."""
    from docker.errors import ImageNotFound

    try:
        docker_client.images.get(image).tag(ref)
    except ImageNotFound:
        return
    repo, tag = ref.rsplit(":", 1)
    for line in docker_client.images.push(repo, tag=tag, stream=True, decode=True):
        assert "error" not in line, line


def arm_containers(on_robot: Callable[[str], str], service: str) -> list[str]:
    """The image reference, the image's architecture and ``uname -m`` inside the running container of
    ``service`` on the arm64 robot's host."""
    out = on_robot(f"c=$(docker ps -q --filter label=com.docker.swarm.service.name={service} | head -1); "
                   "docker inspect --format '{{.Config.Image}} {{.Image}}' $c | "
                   "{ read ref id; echo $ref; docker image inspect --format '{{.Architecture}}' $id; }; "
                   "docker exec $c uname -m")
    return out.split()

