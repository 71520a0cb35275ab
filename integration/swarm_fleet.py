"""Fleets of the demo project on Docker-in-Docker robot hosts: their project folders and their releases.

Shared by ``test_fleet_swarm.py`` and ``bench/fleet.py``. Host 0 of a :class:`RobotFleet` is the Swarm manager
(a DinD host of its own: a manager's advertise address may not be loopback, and this machine's daemon is shared);
the other hosts are robot hosts. A project's robots are all of one model (its robot.yaml):

- one host (``robot``): discovery server, talker and listener on it;
- two hosts (``main``: discovery server and talker; ``aux``: listener), so the listener hears the talker across
  the robot's own network, through the robot's own discovery server.

Releases are self-contained images (the demo's component image plus its install tree at /robocore/install, what
``release --fleet`` makes) pushed to the registry every host reaches as the same 127.0.0.1:PORT, and written as
release records ``.robocore/releases/V.json`` naming each image by digest. Every project of a test gets the same
records: the images do not depend on where a component runs.
"""

from __future__ import annotations

import contextlib
import json
import shutil
from collections.abc import Iterator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import yaml
from deploy_helpers import copy_project
from robot_host.hosts import RobotFleet

from robocore.plan.starts import docker_epoch

#: Where the talker's code is in its install tree (what a release of a changed talker changes).
TALKER_PY = "demo_talker/lib/python3.11/site-packages/demo_talker/talker.py"
#: The release variants: the demo as built, a talker that says "v2", a talker that exits 3 at start, a talker that
#: says "v4" (a release no robot holds yet: swarm_faults' registry-down test), a talker that runs as a node but
#: publishes on another topic (a silent canary: it runs, and /chatter is not heard).
VARIANTS = ("same", "v2", "crash", "v4", "silent")
#: The hosts of a robot of one host, and of two (the first runs the discovery server and the talker).
ONE_HOST = ("robot",)
TWO_HOSTS = ("main", "aux")


def make_project(demo: Path, parent: Path, name: str, hosts: RobotFleet, registry: str, *,
                 waves: Sequence[dict[str, Any]], robots: Mapping[str, Sequence[int]] | None = None,
                 running: int = 3, robot_timeout: int = 90, wave_timeout: int = 600) -> Path:
    """The demo project as a fleet managed by host 0: ``robots`` maps each robot's name to the indexes of its hosts
    in ``hosts`` (all robots with the same number of hosts: one robot.yaml); by default r1..rN, one host each."""
    if robots is None:
        robots = {f"r{i}": (i,) for i in range(1, len(hosts.hosts))}
    (count,) = {len(indexes) for indexes in robots.values()}
    names = ONE_HOST if count == 1 else TWO_HOSTS

    def edit(data: dict[str, Any]) -> None:
        data["hosts"] = [{"name": host, "ip": f"192.0.2.{10 + i}", "user": "root"} for i, host in enumerate(names)]
        data["discovery"] = {"servers": [{"host": names[0], "port": 11811}], "transport": "shm"}
        for component in data["components"]:
            component["runs_on"] = names[-1] if component["name"] == "listener" else names[0]
            if component["name"] == "listener":  # robot.yaml's resources, as the services carry them
                component["resources"] = {"requests": {"cpu": 0.25, "memory": "64Mi"},
                                          "limits": {"cpu": "500m", "memory": "256Mi"}}

    root = copy_project(demo, parent, name, edit=edit)
    fleet = {
        "engine": "swarm",
        "manager": {"ip": hosts.hosts[0].ip, "user": "root"},
        "registry": registry,
        "robots": [{"name": robot, "labels": {"site": "a" if i < len(robots) // 2 else "b"},
                    "hosts": {host: {"ip": hosts.hosts[index].ip} for host, index in zip(names, indexes, strict=True)}}
                   for i, (robot, indexes) in enumerate(robots.items())],
        "rollout": {
            "waves": list(waves),
            "health": {"running": running, "nodes": ["/talker", "/listener"], "heard": ["/chatter"]},
            "timeouts": {"robot": robot_timeout, "wave": wave_timeout},
        },
    }
    (root / "fleet.yaml").write_text(yaml.safe_dump(fleet, sort_keys=False))
    return root


def _push(docker_client: Any, ref: str) -> str:
    """Push ``ref`` (``registry/repo:tag``); ``registry/repo@sha256:...`` as the push recorded it."""
    repo, tag = ref.rsplit(":", 1)
    for line in docker_client.images.push(repo, tag=tag, stream=True, decode=True):
        assert "error" not in line, line
    digests = [d for d in docker_client.api.inspect_image(ref).get("RepoDigests", []) if d.startswith(repo + "@")]
    assert digests, f"no digest of {ref} after its push"
    return str(digests[0])


#: The demo's image prefix, which every copy keeps (deploy_helpers.copy_project): the local images the releases are
#: made from, and their repositories in the registry, as robocore believes a release record only when each image
#: is that component's repository in the fleet's registry.
PREFIX = "robocore-it-demo-"


def push_base(docker_client: Any, registry: str) -> str:
    """Push the demo's base image (what discovery servers and the health probe run); its digest reference."""
    base_ref = f"{registry}/{PREFIX}base:fleet"
    docker_client.images.get(f"{PREFIX}base:latest").tag(base_ref)
    return _push(docker_client, base_ref)


def make_releases(docker_client: Any, demo: Path, registry: str, contexts: Path,
                  versions: dict[str, str], base: str | None = None) -> dict[str, str]:
    """Push each release of ``versions`` (version -> variant of :data:`VARIANTS`) under :data:`PREFIX`'s repositories,
    with ``base`` (:func:`push_base`'s reference; pushed here when None); version -> its release record (the
    file's text, see :func:`write_records`)."""
    if base is None:
        base = push_base(docker_client, registry)
    records = {}
    built: dict[tuple[str, str], str] = {}  # (component, variant) -> pushed: the listener is the same in each
    for version, variant in versions.items():
        refs = {}
        for component in ("talker", "listener"):
            same = built.get((component, variant if component == "talker" else "same"))
            if same is not None:
                refs[component] = same
                continue
            context = contexts / f"{component}-{version}"
            shutil.rmtree(context, ignore_errors=True)
            shutil.copytree(demo / ".robocore" / "build" / component / "install", context / "install", symlinks=True)
            code = context / "install" / TALKER_PY
            if component == "talker" and variant in ("v2", "v4"):
                code.write_text(code.read_text().replace("hello from talker", f"hello {variant} from talker"))
            if component == "talker" and variant == "silent":
                assert '"chatter"' in code.read_text(), code
                code.write_text(code.read_text().replace('"chatter"', '"chatter_elsewhere"'))
            if component == "talker" and variant == "crash":
                code.write_text("raise SystemExit(3)\n" + code.read_text())
            (context / "Dockerfile").write_text(f"FROM {PREFIX}{component}:latest\n"
                                                "COPY install /robocore/install\n")
            ref = f"{registry}/{PREFIX}{component}:{version}"
            docker_client.images.build(path=str(context), tag=ref, rm=True)
            refs[component] = built[(component, variant if component == "talker" else "same")] = \
                _push(docker_client, ref)
        records[version] = json.dumps({"format": 1, "version": version, "registry": registry,
                                       "components": {c: {"amd64": r} for c, r in refs.items()},
                                       "base": {"amd64": base}})
    return records


def write_records(root: Path, records: Mapping[str, str]) -> None:
    """Write ``records`` (version -> text) as project ``root``'s release records."""
    folder = root / ".robocore" / "releases"
    folder.mkdir(parents=True, exist_ok=True)
    for version, text in records.items():
        (folder / f"{version}.json").write_text(text)
        (folder / f"{version}.json").chmod(0o600)


def remove_pushed_tags(docker_client: Any, registry: str) -> None:
    """Remove this machine's tags under ``registry`` (what :func:`make_releases` built and pushed)."""
    for image in docker_client.images.list():
        for tag in image.tags:
            if tag.startswith(f"{registry}/"):
                with contextlib.suppress(Exception):
                    docker_client.images.remove(tag)


def cut(hosts: RobotFleet, index: int, cut_off: bool) -> None:
    """Cut robot host ``index`` off the network (every packet of its eth0 dropped) or reconnect it, from outside:
    the robot keeps running, as a robot that lost its Wi-Fi does."""
    action = "-I" if cut_off else "-D"
    container = hosts.hosts[index].container.get_wrapped_container()
    for rule in (["INPUT", "-i", "eth0", "-j", "DROP"], ["OUTPUT", "-o", "eth0", "-j", "DROP"]):
        code, out = container.exec_run(["iptables", action, *rule])
        assert code == 0, out


def listener_lines(hosts: RobotFleet, index: int, project: str, robot: str | None = None) -> list[str]:
    """What ``robot``'s listener (default: robot ``r<index>``), on host ``index``, printed lately, read on that
    host (not through the manager)."""
    service = f"{project}-{robot or f'r{index}'}-listener"
    out = hosts.hosts[index].ssh(hosts, "sh", "-c", f"docker ps -q --filter label=com.docker.swarm.service.name="
                                 f"{service} | head -1 | xargs -r docker logs --tail 20 2>&1", check=False)
    return [line for line in out.splitlines() if "I heard" in line]


@contextlib.contextmanager
def parallel(workers: int) -> Iterator[ThreadPoolExecutor]:
    """A thread pool for a few things done at once (robocore commands, pulls)."""
    with ThreadPoolExecutor(max_workers=workers) as pool:
        yield pool


def prepull(hosts: RobotFleet, base: str, indexes: Sequence[int]) -> None:
    """Pull the base image ``base`` (by digest, from the registry) on the hosts of ``indexes`` at once, as robots
    already holding their model's base before its first release do; the rollouts then pull only the release's
    small layers (the talker's and listener's images are the base plus a few)."""
    with parallel(len(indexes)) as pool:
        list(pool.map(lambda i: hosts.hosts[i].ssh(hosts, "docker", "pull", "-q", base, timeout=900), indexes))


def container_lives(hosts: RobotFleet, index: int, since: float, until: float) -> list[tuple[str, float, float | None]]:
    """Every Swarm task container on host ``index`` that ran at some time from ``since`` to ``until`` (seconds since
    the epoch; the hosts share this machine's clock): (service, started, stopped or None while it runs). Read on
    the host, not through the manager: the containers it still has (Swarm keeps those of a service's last tasks,
    stopped ones too) and, for those removed since (a removed service's), the daemon's start and die events of the
    period. A container already running at ``since`` that is gone counts from ``since``."""
    fmt = ('{{.Id}} {{index .Config.Labels "com.docker.swarm.service.name"}} {{.State.Running}} {{.State.StartedAt}} '
           "{{.State.FinishedAt}}")
    events = ('{{.TimeNano}} {{.Action}} {{.ID}} {{index .Actor.Attributes "com.docker.swarm.service.name"}}')
    script = ("docker ps -aq --filter label=com.docker.swarm.service.name | xargs -r docker inspect --format \"$1\"; "
              "echo ---; docker events --since \"$3\" --until \"$4\" --filter type=container --filter event=start "
              "--filter event=die --format \"$2\"")
    out = hosts.hosts[index].ssh(hosts, "sh", "-c", script, "sh", fmt, events, str(int(since)), str(int(until) + 1))
    kept, _, logged = out.partition("---\n")
    lives: dict[str, tuple[str, float, float | None]] = {}
    for line in kept.splitlines():
        container, service, running, started, finished = line.split()
        if not started.startswith("0001-"):  # made, never started
            lives[container] = (service, docker_epoch(started), None if running == "true" else docker_epoch(finished))
    for line in logged.splitlines():
        stamp, action, container, *service = line.split()
        if container in lives or not service:
            continue
        when = int(stamp) / 1e9
        name, begin, end = lives.get("removed-" + container, (service[0], since, None))
        lives["removed-" + container] = (name, when, end) if action == "start" else (name, begin, when)
    return [life for life in lives.values() if (life[2] is None or life[2] >= since) and life[1] <= until]


def overlaps(lives: Sequence[tuple[str, float, float | None]], since: float,
             until: float) -> list[tuple[str, float, float]]:
    """Where two containers of one service ran at once between ``since`` and ``until`` (service, from, to)."""
    found = []
    for i, (service, start, stop) in enumerate(lives):
        for other, start2, stop2 in lives[i + 1:]:
            if other != service:
                continue
            begin = max(start, start2, since)
            end = min(stop if stop is not None else until, stop2 if stop2 is not None else until, until)
            if begin < end:
                found.append((service, begin, end))
    return found
