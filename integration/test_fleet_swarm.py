"""Fleets on Docker Swarm: simulated robot hosts joined to one swarm, releases rolled out in waves behind the gate.

One swarm for the module: a Docker-in-Docker host of its own as the manager (a manager's advertise address may
not be loopback, and this machine's daemon is shared), and nine DinD robot hosts reached over ssh:// as real
robots are, holding seven robots of three fleets (a fleet is one robot.yaml model, so robots with a different
number of hosts or another ROS are other projects; all join the same swarm):

- ``robocore-it-swarm``: r1..r4, one host each (discovery server, talker, listener); waves: canary r1, the rest;
- ``robocore-it-swarm-duo``: r5 and r6, two hosts each (``main``: discovery server and talker; ``aux``: the
  listener, which hears the talker across hosts through its robot's own discovery server); one wave;
- ``robocore-it-arm64``: a1, one arm64 host through qemu, ROS 1 noetic (ROS 2 has no aarch64 wheels here): the
  master, the C++ talker and the Python listener, gated by the ROS 1 probe (:mod:`swarm_arm64`).

The ROS 2 fleets' releases are self-contained images (component image + its install tree) pushed to Debian's
docker-registry, which every host reaches as the same 127.0.0.1:PORT (local_registry); services name them by
digest, so no robot is synced. The demo project's images are reused (the session's ``demo_project``); the hosts
start while the releases are pushed. The arm64 fleet's releases are made by ``build`` and ``release --fleet``
under emulation, in the background while the others join and roll out. The fleets' rollouts run side by side.

The tests run in order on the same swarm: join (twice: the second changes nothing); v1 to every robot, heard on
each; v2 with r4 cut off (pending, its containers untouched, then converging alone once reconnected) and heard on
every robot; a canary whose v3 crashes, and an arm64 v3 whose talker is no ROS node (each rollout stops, the robot
is back on v2 and heard, nothing else changed); a fleet rollback of every fleet to v1, every robot back by digest
and heard, with no two containers of one service at once on any robot host meanwhile; a component with a device
refused before anything changes.
"""

from __future__ import annotations

import contextlib
import json
import subprocess
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import yaml
from conftest import RobocoreCli
from deploy_helpers import wait_for
from local_registry import registry_tunnels, serve_registry
from robot_host.hosts import RobotFleet
from swarm_arm64 import (
    ARM,
    CONTROL_TIMEOUT,
    ROBOT,
    ArmReleases,
    arm_containers,
    make_arm_project,
    pushed_early,
    record,
    set_robot_timeout,
    write_fleet,
)
from swarm_fleet import (
    container_lives,
    cut,
    listener_lines,
    make_project,
    make_releases,
    overlaps,
    parallel,
    prepull,
    push_base,
    remove_pushed_tags,
    write_records,
)

pytestmark = pytest.mark.docker

SOLO, DUO = "robocore-it-swarm", "robocore-it-swarm-duo"
#: Each project's robots and the indexes of their hosts (host 0 is the manager).
ROBOTS = {SOLO: {"r1": (1,), "r2": (2,), "r3": (3,), "r4": (4,)}, DUO: {"r5": (5, 6), "r6": (7, 8)},
          ARM: {ROBOT: (9,)}}
HOSTS = 10
ARM_HOST = ROBOTS[ARM][ROBOT][0]
#: The robot cut off during the rollout of v2 (the last of the first fleet's last wave).
OFFLINE = "r4"
VERSIONS = {"v1": "same", "v2": "v2", "v3": "crash"}


@dataclass(frozen=True)
class Swarm:
    """The module's hosts and its fleets' project folders."""

    hosts: RobotFleet
    roots: dict[str, Path]
    #: The releases being pushed and recorded, then the base image pulled on every robot host, while the robots
    #: join: the first rollout waits for it.
    released: Future[None]
    #: The arm64 fleet's releases, made under emulation meanwhile, and its base pulled on its host after v1's.
    arm: ArmReleases
    arm_pulled: Future[None]

    def talker_host(self, robot: str) -> int:
        return next(hosts for robots in ROBOTS.values() for name, hosts in robots.items() if name == robot)[0]

    def listener_host(self, robot: str) -> int:
        return next(hosts for robots in ROBOTS.values() for name, hosts in robots.items() if name == robot)[-1]

    def project_of(self, robot: str) -> str:
        return next(p for p, robots in ROBOTS.items() if robot in robots)

    def heard(self, robot: str) -> list[str]:
        return listener_lines(self.hosts, self.listener_host(robot), self.project_of(robot), robot)

    def on_arm(self, script: str) -> str:
        return self.hosts.hosts[ARM_HOST].ssh(self.hosts, "sh", "-c", script)

    def ready(self, project: str, version: str) -> None:
        """Wait until ``version`` of ``project`` can be rolled out."""
        if project == ARM:
            self.arm.ready(version)
            if version == "v1":
                self.arm_pulled.result()
        else:
            self.released.result()


@pytest.fixture(scope="module")
def fleets(robot_fleets: Callable[..., RobotFleet], demo_project: Path, docker_client: Any, run_robocore: RobocoreCli,
           tmp_path_factory: pytest.TempPathFactory, arm64_images: None) -> Iterator[Swarm]:
    """The hosts, the registry and the fleets' projects; in the background, while the first test joins the robots,
    the ROS 2 releases v1, v2 (the talker says v2) and v3 (the talker exits 3 at start) pushed and recorded by
    digest, and the base image pulled on every ROS 2 robot host (as a robot of a model already holds it); and the
    arm64 fleet's releases built and released by robocore under emulation, one after the other."""
    contexts = tmp_path_factory.mktemp("swarm-images")
    timings: dict[str, float] = {}
    with parallel(6) as pool, parallel(1) as arm_pool, \
            serve_registry(None, tmp_path_factory.mktemp("swarm-registry")) as registry:
        started = pool.submit(robot_fleets, HOSTS)  # the hosts start while the releases are built and pushed
        based = pool.submit(push_base, docker_client, SOLO, registry)
        pushed = pool.submit(lambda: make_releases(docker_client, demo_project, SOLO, registry, contexts, VERSIONS,
                                                   based.result()))
        arm_root = make_arm_project(tmp_path_factory.mktemp("fleet-arm64"), registry)
        early = pool.submit(pushed_early, docker_client, f"{ARM}-base:latest-arm64", f"{registry}/{ARM}-base:early")
        arm = ArmReleases(arm_root, run_robocore, arm_pool, timings, early.result)
        try:
            hosts = started.result()
            write_fleet(arm_root, hosts.hosts[0].ip, hosts.hosts[ARM_HOST].ip, registry)
            with registry_tunnels(hosts, registry):
                parent = tmp_path_factory.mktemp("swarm")
                roots = {ARM: arm_root}
                for project, robots in ROBOTS.items():
                    if project == ARM:
                        continue
                    waves = [{"name": "canary", "robots": ["r1"]}] if project == SOLO else []
                    roots[project] = make_project(demo_project, parent, project, hosts, registry, waves=waves,
                                                  robots=robots, running=2, robot_timeout=120)

                def released() -> None:  # while the robots join; the base pulled while the releases are pushed
                    prepull(hosts, based.result(), [i for i in range(1, HOSTS) if i != ARM_HOST])
                    records = pushed.result()
                    for project, root in roots.items():
                        if project != ARM:
                            write_records(root, records)

                def arm_pulled() -> None:  # the arm64 base (~800 MB) on its robot, as its model's robots hold it
                    arm.ready("v1")
                    prepull(hosts, record(arm_root, "v1")["base"]["arm64"], [ARM_HOST])

                yield Swarm(hosts, roots, pool.submit(released), arm, pool.submit(arm_pulled))
        finally:
            print("arm64 fleet steps (s):", timings)
            with contextlib.suppress(Exception):
                pushed.result()  # its tags exist before they are removed
            with contextlib.suppress(Exception):
                arm.ready("v3")
            remove_pushed_tags(docker_client, registry)


def every(run_robocore: RobocoreCli, swarm: Swarm, *args: str, version: str | None = None,
          first: dict[str, Callable[[], object]] | None = None) -> dict[str, subprocess.CompletedProcess[str]]:
    """``robocore fleet ARGS --json`` on every fleet at once, each once ``version`` of it is ready (when given)
    and ``first[project]`` has run; project -> its completed command. Each command's seconds are in
    :data:`TOOK`."""
    def one(project: str) -> subprocess.CompletedProcess[str]:
        if version is not None:
            swarm.ready(project, version)
        if first and project in first:
            first[project]()
        began = time.monotonic()
        try:
            return run_robocore(swarm.roots[project], "fleet", *args, "--json", check=False)
        finally:
            TOOK[project] = time.monotonic() - began

    with parallel(len(ROBOTS)) as pool:
        done = {project: pool.submit(one, project) for project in ROBOTS}
        return {project: future.result() for project, future in done.items()}


#: Seconds each fleet's last command of :func:`every` took.
TOOK: dict[str, float] = {}


def verdicts(proc: subprocess.CompletedProcess[str]) -> dict[str, str]:
    """robot -> its verdict, from a rollout's JSON envelope."""
    return {o["robot"]: o["verdict"] for o in json.loads(proc.stdout)["results"] if o["kind"] == "fleet_robot_change"}


def status_rows(run_robocore: RobocoreCli, root: Path) -> dict[str, dict[str, Any]]:
    """``fleet status --json``: robot -> row."""
    proc = run_robocore(root, "fleet", "status", "--json")
    envelope = json.loads(proc.stdout)
    assert envelope["ok"] is True, envelope
    return {r["robot"]: r for r in envelope["results"] if r["kind"] == "fleet_robot"}


def service_specs(swarm: Swarm, project: str, robots: list[str]) -> dict[str, str]:
    """The services of ``robots`` of ``project`` as the manager stores them (name -> its spec as JSON): what
    robocore sets on a change (image, release labels). Unchanged specs mean the robots were not touched; their
    tasks are not compared, as Swarm replaces a task on its own (e.g. on a node that has just reconnected)."""
    fmt = "{{.Spec.Name}} {{json .Spec}}"
    out = swarm.hosts.hosts[0].ssh(swarm.hosts, "sh", "-c", "docker service ls -q --filter label=dev.robocore.project="
                                   f"{project} | xargs -r docker service inspect --format '{fmt}'")
    specs = dict(line.split(" ", 1) for line in out.splitlines() if line.strip())
    mine = {name: spec for name, spec in specs.items() if any(name.startswith(f"{project}-{r}-") for r in robots)}
    assert mine and not any("-probe-" in name for name in mine), sorted(specs)
    return mine


def test_join_labels_every_robot_node_and_is_idempotent(fleets: Swarm, run_robocore: RobocoreCli) -> None:
    first = json.loads(run_robocore(fleets.roots[SOLO], "fleet", "join", "--json").stdout)  # makes the swarm
    assert first["ok"] is True
    assert {(r["robot"], r["host"], r["action"]) for r in first["results"]} == \
        {(robot, "robot", "joined") for robot in ROBOTS[SOLO]}
    done = every(run_robocore, fleets, "join")  # the other fleets join the same swarm; the first's again
    duo, arm, again = (json.loads(done[p].stdout) for p in (DUO, ARM, SOLO))
    assert {(r["robot"], r["host"], r["action"]) for r in duo["results"]} == \
        {(robot, host, "joined") for robot in ROBOTS[DUO] for host in ("main", "aux")}, done[DUO].stderr
    assert {(r["robot"], r["host"], r["action"]) for r in arm["results"]} == {(ROBOT, "robot", "joined")}, arm
    assert {r["action"] for r in again["results"]} == {"unchanged"}, again
    labels = fleets.hosts.hosts[0].ssh(fleets.hosts, "sh", "-c", "docker node ls -q | xargs docker node inspect "
                                       "--format '{{.Description.Hostname}} {{json .Spec.Labels}}'")
    by_host = {line.split(" ", 1)[0]: json.loads(line.split(" ", 1)[1]) or {} for line in labels.splitlines()}
    expected: dict[str, dict[str, str]] = {fleets.hosts.hosts[0].name: {}}  # the manager: no service lands on it
    for project, robots in ROBOTS.items():
        for robot, indexes in robots.items():
            for host, index in zip(("robot",) if len(indexes) == 1 else ("main", "aux"), indexes, strict=True):
                expected[fleets.hosts.hosts[index].name] = {
                    "dev.robocore.project": project, "dev.robocore.robot": robot, "dev.robocore.host": host,
                    "dev.robocore.arch": "arm64" if project == ARM else "amd64"}
    assert by_host == expected


def test_v1_rolls_out_to_every_robot_by_digest_and_is_heard(fleets: Swarm, run_robocore: RobocoreCli) -> None:
    done = every(run_robocore, fleets, "rollout", "v1", version="v1")
    for project, proc in done.items():
        assert proc.returncode == 0, proc.stderr
        assert verdicts(proc) == {robot: "healthy" for robot in ROBOTS[project]}, proc.stderr
    waves = [o["wave"] for o in json.loads(done[SOLO].stdout)["results"] if o["kind"] == "fleet_robot_change"]
    assert waves == ["canary", "rest", "rest", "rest"]
    for project, robots in ROBOTS.items():
        rows = status_rows(run_robocore, fleets.roots[project])
        assert {r: (row["running"], row["target"], row["state"]) for r, row in rows.items()} == \
            {robot: ("v1", "v1", "online") for robot in robots}
    for robot in (r for robots in ROBOTS.values() for r in robots):  # heard on every robot, read on its host
        assert wait_for(lambda r=robot: fleets.heard(r), 60), f"{robot} heard nothing"
        host = fleets.hosts.hosts[fleets.talker_host(robot)]
        project = fleets.project_of(robot)
        image = host.ssh(fleets.hosts, "sh", "-c", "docker ps -q --filter label=com.docker.swarm.service.name="
                         f"{project}-{robot}-talker | xargs docker inspect --format '{{{{.Config.Image}}}}'")
        assert "@sha256:" in image, image  # by digest
    # the arm64 robot: its master, talker and listener run the arm64 images of the release, by digest, as aarch64
    arm = record(fleets.roots[ARM], "v1")
    assert {c: sorted(images) for c, images in arm["components"].items()} == \
        {"talker": ["arm64"], "listener": ["arm64"]} and sorted(arm["base"]) == ["arm64"], arm
    for part, image in (("discovery-0", arm["base"]["arm64"]), ("talker", arm["components"]["talker"]["arm64"]),
                        ("listener", arm["components"]["listener"]["arm64"])):
        assert arm_containers(fleets.on_arm, f"{ARM}-{ROBOT}-{part}") == [image, "arm64", "aarch64"], part
    for host in fleets.hosts.hosts[1:]:
        assert "robocore" not in host.ssh(fleets.hosts, "ls", "-A", "/root").split()  # nothing synced
    text = run_robocore(fleets.roots[SOLO], "fleet", "status").stdout
    assert text.splitlines()[0].split()[:3] == ["ROBOT", "RUNNING", "TARGET"]


def test_v2_reaches_every_robot_and_an_offline_one_converges_alone(fleets: Swarm, run_robocore: RobocoreCli) -> None:
    offline = fleets.talker_host(OFFLINE)
    cut(fleets.hosts, offline, True)
    try:
        def down() -> bool:
            return bool(status_rows(run_robocore, fleets.roots[SOLO])[OFFLINE]["state"].startswith("offline"))

        def seen_down() -> None:  # cut off before its wave: the manager sees it down before the rollout starts
            assert wait_for(down, 90, interval=2), "the manager never saw the cut robot down"

        done = every(run_robocore, fleets, "rollout", "v2", version="v2", first={SOLO: seen_down})
        for project in (DUO, ARM):
            assert done[project].returncode == 0, done[project].stderr
            assert verdicts(done[project]) == {robot: "healthy" for robot in ROBOTS[project]}, done[project].stderr
        assert verdicts(done[SOLO]) == {**{r: "healthy" for r in ROBOTS[SOLO]}, OFFLINE: "pending"}, done[SOLO].stderr
        assert done[SOLO].returncode == 0, done[SOLO].stderr  # a pending robot does not fail the rollout
        assert TOOK[SOLO] < 300, TOOK
        row = status_rows(run_robocore, fleets.roots[SOLO])[OFFLINE]
        # not on v2: unknown once the manager dropped the down node's tasks, else the v1 it last ran
        assert row["running"] in ("?", "v1") and (row["target"], row["state"]) == ("v2", "offline, pending"), row
        # its containers were left alone: still the v1 talker, still running (read on the host, not over the cut)
        container = fleets.hosts.hosts[offline].container.get_wrapped_container()
        code, out = container.exec_run(["sh", "-c", "docker ps -q --filter label=com.docker.swarm.service.name="
                                        f"{SOLO}-{OFFLINE}-talker | xargs docker inspect --format "
                                        "'{{.Config.Image}} {{.State.Status}}'"])
        v1 = record(fleets.roots[SOLO], "v1")["components"]["talker"]
        assert (code, out.decode().split()) == (0, [v1["amd64"], "running"]), out
    finally:
        cut(fleets.hosts, offline, False)
    for robot in (r for robots in ROBOTS.values() for r in robots if r != OFFLINE):
        assert wait_for(lambda r=robot: any("hello v2" in line for line in fleets.heard(r)), 60), fleets.heard(robot)

    def converged() -> bool:  # no command: Swarm gives the reconnected node its services' current spec
        row = status_rows(run_robocore, fleets.roots[SOLO])[OFFLINE]
        return (row["running"], row["state"]) == ("v2", "online")

    assert wait_for(converged, 150, interval=2), status_rows(run_robocore, fleets.roots[SOLO])[OFFLINE]
    assert wait_for(lambda: any("hello v2" in line for line in fleets.heard(OFFLINE)), 60), fleets.heard(OFFLINE)


def test_canary_that_crashes_stops_the_rollout_and_goes_back(fleets: Swarm, run_robocore: RobocoreCli) -> None:
    """The ROS 2 fleet's canary whose v3 talker exits at start and, side by side, the arm64 fleet's v3 whose talker
    runs but is no ROS node (every container runs, yet the ROS 1 gate finds /talker missing and /chatter unheard):
    each rollout stops and the robot is back on v2, gated again and heard."""
    later = [r for r in ROBOTS[SOLO] if r != "r1"]
    before, canary = service_specs(fleets, SOLO, later), service_specs(fleets, SOLO, ["r1"])
    fleets.ready(ARM, "v3")
    original = set_robot_timeout(fleets.roots[ARM], CONTROL_TIMEOUT)  # the probe waits this long for the talker
    try:
        with parallel(1) as pool:
            arm = pool.submit(run_robocore, fleets.roots[ARM], "fleet", "rollout", "v3", check=False)
            proc = run_robocore(fleets.roots[SOLO], "fleet", "rollout", "v3", check=False)
            arm_proc = arm.result()
    finally:
        (fleets.roots[ARM] / "fleet.yaml").write_text(original)
    assert proc.returncode != 0
    assert "stopped in wave canary" in proc.stderr and "r1" in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr
    assert "r1: back on v2: healthy" in proc.stderr, proc.stderr  # gated again: running, nodes present, heard

    def back() -> dict[str, Any] | None:
        row = status_rows(run_robocore, fleets.roots[SOLO])["r1"]
        return row if (row["running"], row["target"], row["health"]) == ("v2", "v2", "rolled-back") else None

    assert wait_for(back, 30, interval=1), status_rows(run_robocore, fleets.roots[SOLO])["r1"]
    rows = status_rows(run_robocore, fleets.roots[SOLO])
    assert all(rows[r]["target"] == "v2" for r in later), rows
    assert service_specs(fleets, SOLO, later) == before  # the later wave untouched: no service of it changed
    assert service_specs(fleets, SOLO, ["r1"]) != canary  # (the canary's were: the comparison sees a change)
    assert wait_for(lambda: any("hello v2" in line for line in fleets.heard("r1")), 30), fleets.heard("r1")

    stderr = arm_proc.stderr
    assert arm_proc.returncode != 0 and "Traceback" not in stderr, stderr
    assert "nodes missing: /talker" in stderr and "not heard: /chatter" in stderr, stderr
    assert "/listener" not in stderr.split("nodes missing:", 1)[1].split(";")[0], stderr  # only the talker
    assert f"{ROBOT}: back on v2: healthy" in stderr, stderr  # gated again: the ROS 1 probe passes on v2
    row = status_rows(run_robocore, fleets.roots[ARM])[ROBOT]
    assert (row["running"], row["target"], row["health"]) == ("v2", "v2", "rolled-back"), row
    assert wait_for(lambda: any("hello v2 from talker" in line for line in fleets.heard(ROBOT)[-3:]), 60), \
        fleets.heard(ROBOT)


def test_fleet_rollback_returns_every_robot_stop_first(fleets: Swarm, run_robocore: RobocoreCli) -> None:
    """Every fleet from v2 back to v1: every robot healthy, runs v1's talker by digest and is heard saying v1; no
    two containers of one service ran at once on any robot host during the rollback (read on each host: the task
    containers Swarm keeps, with their start and stop times, and the daemon's events for any removed since)."""
    started = time.time()
    done = every(run_robocore, fleets, "rollback")
    ended = time.time()
    for project, proc in done.items():
        assert proc.returncode == 0, proc.stderr
        assert verdicts(proc) == {robot: "healthy" for robot in ROBOTS[project]}, proc.stderr
    # the goal for a fleet's rollback (bench/fleet.py: 10 robots); the emulated arm64 robot's gate is slower
    assert TOOK[SOLO] < 120 and TOOK[DUO] < 120 and TOOK[ARM] < 240, TOOK
    for project, robots in ROBOTS.items():
        v1 = record(fleets.roots[project], "v1")["components"]["talker"]
        rows = status_rows(run_robocore, fleets.roots[project])
        assert {r: (row["running"], row["target"], row["health"]) for r, row in rows.items()} == \
            {robot: ("v1", "v1", "healthy") for robot in robots}, rows
        for robot in robots:
            host = fleets.hosts.hosts[fleets.talker_host(robot)]
            image = host.ssh(fleets.hosts, "sh", "-c", "docker ps -q --filter label=com.docker.swarm.service.name="
                             f"{project}-{robot}-talker | xargs docker inspect --format '{{{{.Config.Image}}}}'")
            assert image.split() == [v1["arm64" if project == ARM else "amd64"]], image  # one talker, v1's

    def heard_v1(robot: str) -> bool:
        return wait_for(lambda: any("hello from talker" in line for line in fleets.heard(robot)[-3:]), 60)

    everyone = [r for robots in ROBOTS.values() for r in robots]
    with parallel(len(everyone)) as pool:
        heard = dict(zip(everyone, pool.map(heard_v1, everyone), strict=True))
    assert all(heard.values()), {robot: fleets.heard(robot) for robot, ok in heard.items() if not ok}
    now = time.time()
    with parallel(HOSTS - 1) as pool:  # every robot host at once
        read = dict(zip(range(1, HOSTS), pool.map(lambda i: container_lives(fleets.hosts, i, started, now),
                                                  range(1, HOSTS)), strict=True))
    lives_of = {i: [life for life in lives if "-probe-" not in life[0]] for i, lives in read.items()}
    assert overlaps([("s", 1.0, 3.0), ("s", 2.0, None), ("t", 0.0, None)], 0.0, 5.0) == [("s", 2.0, 3.0)]  # control
    for robots in ROBOTS.values():
        for robot, indexes in robots.items():
            for index in indexes:
                lives = lives_of[index]
                assert not overlaps(lives, started, now), (robot, index, sorted(lives, key=lambda life: life[1]))
            talker = [life for life in lives_of[indexes[0]] if life[0].endswith("-talker")]
            # the check saw the swap: the v2 talker stopped and the v1 talker started within the rollback
            assert any(stop is not None and started <= stop <= ended for _, _, stop in talker), talker
            assert any(started <= start <= ended for _, start, _ in talker), talker


def test_device_component_is_refused_before_anything_changes(fleets: Swarm, run_robocore: RobocoreCli) -> None:
    robot_file = fleets.roots[SOLO] / "robot.yaml"
    original = robot_file.read_text()
    before = service_specs(fleets, SOLO, list(ROBOTS[SOLO]))
    data = yaml.safe_load(original)
    data["components"][0]["devices"] = ["/dev/ttyUSB0"]
    robot_file.write_text(yaml.safe_dump(data, sort_keys=False))
    try:
        proc = run_robocore(fleets.roots[SOLO], "fleet", "rollout", "v1", check=False)
    finally:
        robot_file.write_text(original)
    assert proc.returncode == 2, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
    assert len(lines) == 1 and "robot.yaml:" in lines[0] and "devices" in lines[0], proc.stderr
    assert service_specs(fleets, SOLO, list(ROBOTS[SOLO])) == before
