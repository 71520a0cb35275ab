"""A fleet of the demo project on Docker-in-Docker robot hosts: its project folder and its releases.

Shared by ``test_fleet_swarm.py`` and ``bench/fleet.py``. Host 0 of a :class:`RobotFleet` is the Swarm manager
(a DinD host of its own: a manager's advertise address may not be loopback, and this machine's daemon is shared);
hosts 1..N are the robots r1..rN, each a one-host robot of the demo project (discovery server, talker, listener).

Releases are self-contained images (the demo's component image plus its install tree at /robocore/install, what
``release --fleet`` makes) pushed to the registry every host reaches as the same 127.0.0.1:PORT, and written as
release records ``.robocore/releases/V.json`` naming each image by digest.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import yaml
from deploy_helpers import copy_project
from robot_host.hosts import RobotFleet

#: Where the talker's code is in its install tree (what a release of a changed talker changes).
TALKER_PY = "demo_talker/lib/python3.11/site-packages/demo_talker/talker.py"
#: The release variants: the demo as built, a talker that says "v2", a talker that exits 3 at start.
VARIANTS = ("same", "v2", "crash")


def make_project(demo: Path, parent: Path, name: str, hosts: RobotFleet, registry: str, *,
                 waves: Sequence[dict[str, Any]], running: int = 3, robot_timeout: int = 90) -> Path:
    """The demo project as a fleet of ``len(hosts.hosts) - 1`` one-host robots (r1..rN) managed by host 0."""

    def edit(data: dict[str, Any]) -> None:
        data["hosts"] = [{"name": "robot", "ip": "192.0.2.10", "user": "root"}]
        data["discovery"] = {"servers": [{"host": "robot", "port": 11811}], "transport": "shm"}
        for component in data["components"]:
            component["runs_on"] = "robot"

    root = copy_project(demo, parent, name, edit=edit)
    count = len(hosts.hosts) - 1
    fleet = {
        "engine": "swarm",
        "manager": {"ip": hosts.hosts[0].ip, "user": "root"},
        "registry": registry,
        "robots": [{"name": f"r{i}", "labels": {"site": "a" if i <= count // 2 else "b"},
                    "hosts": {"robot": {"ip": hosts.hosts[i].ip}}} for i in range(1, count + 1)],
        "rollout": {
            "waves": list(waves),
            "health": {"running": running, "nodes": ["/talker", "/listener"], "heard": ["/chatter"]},
            "timeouts": {"robot": robot_timeout, "wave": 600},
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


def make_releases(docker_client: Any, demo: Path, root: Path, registry: str, contexts: Path,
                  versions: dict[str, str]) -> None:
    """Push each release of ``versions`` (version -> variant of :data:`VARIANTS`) and write its record."""
    name = root.name
    base_ref = f"{registry}/{name}-base:fleet"
    docker_client.images.get("robocore-it-demo-base:latest").tag(base_ref)
    base = _push(docker_client, base_ref)
    records = root / ".robocore" / "releases"
    records.mkdir(parents=True, exist_ok=True)
    for version, variant in versions.items():
        refs = {}
        for component in ("talker", "listener"):
            context = contexts / f"{component}-{version}"
            shutil.rmtree(context, ignore_errors=True)
            shutil.copytree(demo / ".robocore" / "build" / component / "install", context / "install", symlinks=True)
            code = context / "install" / TALKER_PY
            if component == "talker" and variant == "v2":
                code.write_text(code.read_text().replace("hello from talker", "hello v2 from talker"))
            if component == "talker" and variant == "crash":
                code.write_text("raise SystemExit(3)\n" + code.read_text())
            (context / "Dockerfile").write_text(f"FROM robocore-it-demo-{component}:latest\n"
                                                "COPY install /robocore/install\n")
            ref = f"{registry}/{name}-{component}:{version}"
            docker_client.images.build(path=str(context), tag=ref, rm=True)
            refs[component] = _push(docker_client, ref)
        record = {"format": 1, "version": version, "registry": registry,
                  "components": {c: {"amd64": r} for c, r in refs.items()}, "base": {"amd64": base}}
        (records / f"{version}.json").write_text(json.dumps(record))


def cut(hosts: RobotFleet, index: int, cut_off: bool) -> None:
    """Cut robot host ``index`` off the network (every packet of its eth0 dropped) or reconnect it, from outside:
    the robot keeps running, as a robot that lost its Wi-Fi does."""
    action = "-I" if cut_off else "-D"
    container = hosts.hosts[index].container.get_wrapped_container()
    for rule in (["INPUT", "-i", "eth0", "-j", "DROP"], ["OUTPUT", "-o", "eth0", "-j", "DROP"]):
        code, out = container.exec_run(["iptables", action, *rule])
        assert code == 0, out


def listener_lines(hosts: RobotFleet, index: int, project: str) -> list[str]:
    """What robot ``index``'s listener printed lately, read on its host (not through the manager)."""
    service = f"{project}-r{index}-listener"
    out = hosts.hosts[index].ssh(hosts, "sh", "-c", f"docker ps -q --filter label=com.docker.swarm.service.name="
                                 f"{service} | head -1 | xargs -r docker logs --tail 20 2>&1", check=False)
    return [line for line in out.splitlines() if "I heard" in line]


def prepull(hosts: RobotFleet, root: Path, version: str) -> None:
    """Pull ``version``'s base image (by digest, from the registry) on every robot host at once, as a robot
    already holding its model's base before its first release does; the rollouts then pull only the release's
    small layers (the talker's and listener's images are the base plus one layer)."""
    from concurrent.futures import ThreadPoolExecutor

    record = json.loads((root / ".robocore" / "releases" / f"{version}.json").read_text())
    base = record["base"]["amd64"]
    with ThreadPoolExecutor(max_workers=len(hosts.hosts)) as pool:
        list(pool.map(lambda host: host.ssh(hosts, "docker", "pull", "-q", base, timeout=600), hosts.hosts[1:]))
