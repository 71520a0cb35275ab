"""A fleet of 10 robots on Docker Swarm: rollout, gate, failed canary, rollback, offline convergence, worker cost.

Ten one-host robots of the demo project (discovery server, talker, listener) on Docker-in-Docker robot hosts, an
eleventh DinD host as the Swarm manager, Debian's docker-registry reached by every host as 127.0.0.1:PORT
(integration/swarm_fleet.py sets it all up, as the integration suite does). Waves: canary (r1), 50 % of the rest,
the rest. Gate: containers up 3 s, /talker and /listener present, /chatter heard.

Measured, one run, printed as one table:
1. v1 to 10 robots (the first release: services created; the base image already on each robot);
2. v2 to 10 robots in 3 waves (the talker changed): whole rollout, and each wave's gate decision (the slowest
   robot of the wave, from its update to its verdict);
3. a failed canary (v3's talker exits at start): until the command returns, with the canary back on v2 and heard;
4. fleet rollback of the 10 robots (v2 -> v1), all gated;
5. an offline robot: cut off (iptables on its host) before a rollout to v2, then reconnected: seconds from the
   reconnection until it runs v2 and is heard, with no command;
6. a robot's cost: RSS and CPU (over 30 s) of dockerd on a Swarm worker running its robot, beside dockerd of a
   plain daemon (a host that never joined) running nothing.

Goals: 10 robots in < 5 min; each wave's gate < 30 s; failed canary back < 60 s; rollback < 2 min;
offline robot converged < 60 s after reconnecting.

    python bench/fleet.py
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from harness import Figure, record

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "integration"))

import docker  # noqa: E402
from deploy_helpers import wait_for  # noqa: E402
from local_registry import serve_registry  # noqa: E402
from robot_host.hosts import RobotFleet  # noqa: E402
from swarm_fleet import (  # noqa: E402
    cut,
    listener_lines,
    make_project,
    make_releases,
    prepull,
    remove_pushed_tags,
    write_records,
)

ROBOTS = 10
NAME = "robocore-it-benchfleet"


def robocore(project: Path | None, *args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    argv = [sys.executable, "-m", "robocore", *(["-p", str(project)] if project else []), *args]
    done = subprocess.run(argv, capture_output=True, text=True, check=False)
    if check and done.returncode != 0:
        raise SystemExit(f"robocore {' '.join(args)} failed ({done.returncode}):\n{done.stdout[-3000:]}"
                         f"{done.stderr[-3000:]}")
    return done


def timed(project: Path, *args: str, check: bool = True) -> tuple[float, list[dict[str, Any]]]:
    started = time.perf_counter()
    done = robocore(project, *args, "--json", check=check)
    took = time.perf_counter() - started
    return took, [r for r in json.loads(done.stdout)["results"] if r.get("kind") == "fleet_robot_change"]


def rows(project: Path) -> dict[str, dict[str, Any]]:
    done = robocore(project, "fleet", "status", "--json")
    return {r["robot"]: r for r in json.loads(done.stdout)["results"]}


def waves_gate(outcomes: list[dict[str, Any]]) -> str:
    by_wave: dict[str, float] = {}
    for outcome in outcomes:
        by_wave[outcome["wave"]] = max(by_wave.get(outcome["wave"], 0.0), outcome["seconds"])
    return ", ".join(f"{wave} {seconds:.1f}" for wave, seconds in by_wave.items())


def dockerd_cost(hosts: RobotFleet, index: int) -> tuple[float, float]:
    """RSS (MiB) of dockerd on host ``index`` and the CPU % it used over 30 s."""
    container = hosts.hosts[index].container.get_wrapped_container()

    def sample() -> tuple[float, float]:
        _, out = container.exec_run(["sh", "-c", "pid=$(pidof dockerd); grep VmRSS /proc/$pid/status | "
                                        "tr -s ' ' | cut -d' ' -f2; cut -d' ' -f14,15 /proc/$pid/stat"])
        lines = out.decode().split()
        return float(lines[0]) / 1024, (float(lines[1]) + float(lines[2])) / 100  # clock ticks (100 Hz)

    _, cpu0 = sample()
    time.sleep(30)
    rss, cpu1 = sample()
    return rss, (cpu1 - cpu0) / 30 * 100


def main() -> None:
    parent = Path(tempfile.mkdtemp(prefix="robocore-bench-fleet-"))
    demo = parent / "robocore-it-demo"
    robocore(None, "init", str(demo), "--defaults", "--base", "wheels")
    for step in ("prepare-base", "stage", "build"):
        robocore(demo, step, "--quiet")
    client = docker.from_env(timeout=600)
    table: list[tuple[str, str, str]] = []
    with RobotFleet(ROBOTS + 2, tag="bfleet") as hosts:  # 0 manager, 1..10 robots, 11 a plain daemon
        hosts.hosts, plain = hosts.hosts[:-1], hosts.hosts[-1]
        (parent / "registry-data").mkdir()
        with serve_registry(hosts, parent / "registry-data") as registry:
            waves = [{"name": "canary", "robots": ["r1"]}, {"name": "half", "percent": 50}, {"name": "rest"}]
            project = make_project(demo, parent, NAME, hosts, registry, waves=waves)
            records = make_releases(client, demo, registry, parent / "contexts",
                                    {"v1": "same", "v2": "v2", "v3": "crash"})
            write_records(project, records)
            prepull(hosts, json.loads(records["v1"])["base"]["amd64"], range(1, ROBOTS + 1))
            robocore(project, "fleet", "join")
            took, out = timed(project, "fleet", "rollout", "v1")
            table.append(("v1 to 10 robots (first release)", f"{took:.1f}", waves_gate(out)))
            took, out = timed(project, "fleet", "rollout", "v2")
            assert all(o["verdict"] == "healthy" for o in out), out
            table.append(("v2 to 10 robots, 3 waves", f"{took:.1f}", "gate per wave: " + waves_gate(out)))
            took, out = timed(project, "fleet", "rollout", "v3", check=False)
            canary = rows(project)["r1"]
            table.append(("failed canary (v3 exits), back on v2", f"{took:.1f}",
                          f"r1 runs {canary['running']}, health {canary['health']}; "
                          f"others changed: {sum(r['target'] != 'v2' for r in rows(project).values())}"))
            took, out = timed(project, "fleet", "rollback", check=False)  # a failed gate is a figure too
            table.append(("fleet rollback of 10 robots (v2 -> v1)", f"{took:.1f}",
                          f"healthy: {sum(o['verdict'] == 'healthy' for o in out)}"))
            cut(hosts, ROBOTS, True)
            wait_for(lambda: rows(project)[f"r{ROBOTS}"]["state"].startswith("offline"), 90, interval=2)
            took, out = timed(project, "fleet", "rollout", "v2")
            cut(hosts, ROBOTS, False)
            back = time.perf_counter()
            wait_for(lambda: rows(project)[f"r{ROBOTS}"]["running"] == "v2", 300, interval=1)
            heard = wait_for(lambda: any("v2" in line for line in listener_lines(hosts, ROBOTS, NAME)), 120, 1)
            table.append(("offline robot: reconnected -> v2 and heard", f"{time.perf_counter() - back:.1f}",
                          f"rollout with it offline {took:.1f} s; heard: {bool(heard)}"))
            hosts.hosts.append(plain)
            worker_rss, worker_cpu = dockerd_cost(hosts, 1)
            plain_rss, plain_cpu = dockerd_cost(hosts, len(hosts.hosts) - 1)
            table.append(("dockerd of a Swarm worker (its robot running)", f"{worker_rss:.0f} MiB",
                          f"{worker_cpu:.1f} % CPU"))
            table.append(("dockerd of a plain daemon (nothing running)", f"{plain_rss:.0f} MiB",
                          f"{plain_cpu:.1f} % CPU"))
            remove_pushed_tags(client, registry)
    client.close()
    width = max(len(r[0]) for r in table)
    print(f"{'fleet of 10 robots on Swarm':<{width}}  {'seconds':>8}  notes")
    for what, value, notes in table:
        print(f"{what:<{width}}  {value:>8}  {notes}")
    record("fleet", [Figure(what, float(value.split()[0]), value.split()[1] if " " in value else "s", detail=notes)
                     for what, value, notes in table],
           goals=["10 robots in < 5 min", "each wave's gate < 30 s", "failed canary back < 60 s", "rollback < 2 min",
                  "offline robot converged < 60 s after reconnecting"])


if __name__ == "__main__":
    main()
