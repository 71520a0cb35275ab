"""robocore's health gate in the cluster: minReadySeconds from rollout.health.running, the health Job (workload check,
then the graph probe of the Swarm gate), and what the controllers then call ready: a robot whose DaemonSets schedule
nothing is not healthy, so Fleet's rollout (tests/fleet_model.py) stops there."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest
import yaml
from fleet_model import Cluster, Objects, roll_out, targets
from k8s_checks import by_kind, render, validate
from test_kubernetes_fleet import AMR, AMR_FLEET, LEGACY, LEGACY_FLEET, write

from robocore import resources
from robocore.commands.export import export_kubernetes
from robocore.commands.support.context import Options

Rendered = dict[str, dict[str, list[dict[str, Any]]]]
GATE = """\
  health: {running: 5, nodes: [/driver, /perception], heard: [/scan]}
  timeouts: {robot: 90}
"""


def export(work: Path, tag: str) -> Path:
    amr = work / "amr"
    if not amr.exists():
        write(amr, AMR, AMR_FLEET + GATE, ("driver", "perception"))
        write(work / "legacy", LEGACY, LEGACY_FLEET, ("talker",))
    folder = work / f"k8s-{tag}"
    export_kubernetes(Options(project_dir=amr, task="export", quiet=True), folder, tag=tag,
                      git_repo="https://git.example.org/fleet.git", models=[work / "legacy"])
    return folder


@pytest.fixture(scope="module")
def work(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("health")


@pytest.fixture(scope="module")
def rendered(work: Path) -> Rendered:
    """Each release's rendered objects of each robot."""
    out = {}
    for tag in ("v1", "v2"):
        folder = export(work, tag)
        out[tag] = {robot: render(folder / "robots" / robot) for robot in ("r1", "r2", "r3")}
    return out


def daemonsets_check() -> dict[str, Any]:
    """The namespace of the Job's workload check script (robocore/resources/k8s-daemonsets), not run as a program."""
    namespace: dict[str, Any] = {"__name__": "k8s_daemonsets"}
    exec(compile(resources.read("k8s-daemonsets").decode(), "k8s-daemonsets", "exec"), namespace)
    return namespace


def test_the_gate_is_in_every_robots_objects(rendered: Rendered) -> None:
    for robot, docs in rendered["v2"].items():
        for doc in docs:
            validate(doc)
        for ds in by_kind(docs, "DaemonSet").values():
            assert ds["spec"]["minReadySeconds"] == (5 if robot != "r3" else 10)  # r3: the default
        (job,) = by_kind(docs, "Job").values()
        pod = job["spec"]["template"]["spec"]
        assert job["spec"]["backoffLimit"] == 0 and pod["restartPolicy"] == "Never"
        assert pod["serviceAccountName"] == "robocore-health"
        assert pod["nodeSelector"]["robocore.dev/robot"] == robot
        (step,) = pod["initContainers"]
        (probe,) = pod["containers"]
        assert step["command"][:2] == ["python3", "/robocore/health/daemonsets.py"]
        if robot == "r3":  # ROS 1: the master's probe, reached as a client on the node's address
            assert probe["args"] == ["python3", "/robocore/health/probe.py", "--timeout", "120"]
            assert {"name": "ROS_IP", "valueFrom": {"fieldRef": {"fieldPath": "status.hostIP"}}} in probe["env"]
            assert {"name": "ROS_MASTER_URI", "value": "http://discovery-base:11311"} in probe["env"]
        else:
            assert probe["args"] == ["python3", "/robocore/health/probe.py", "--timeout", "90", "--node", "/driver",
                                     "--node", "/perception", "--heard", "/scan"]
            assert pod["nodeSelector"]["robocore.dev/host"] == "main"  # the discovery server's host
            assert probe["image"] == "10.0.0.2:5000/amr-base:v2"
        role = by_kind(docs, "Role")["robocore-health"]
        assert role["rules"] == [{"apiGroups": ["apps"], "resources": ["daemonsets"], "verbs": ["get", "list"]}]
        (binding,) = by_kind(docs, "RoleBinding").values()
        assert binding["subjects"] == [{"kind": "ServiceAccount", "name": "robocore-health",
                                        "namespace": f"robot-{robot}"}]
    r2 = {e["name"]: e.get("value") for e in by_kind(rendered["v2"]["r2"], "Job").popitem()[1]["spec"]["template"]
          ["spec"]["containers"][0]["env"]}
    assert r2["ROS_DOMAIN_ID"] == "7"  # the robot's own domain reaches the probe too


def test_a_new_release_is_a_new_job(rendered: Rendered) -> None:
    """A Job's pods cannot change: its name changes with everything they hold, and only then."""
    names = {tag: {robot: list(by_kind(docs, "Job")) for robot, docs in robots.items()}
             for tag, robots in rendered.items()}
    assert names["v1"]["r1"] == names["v1"]["r2"] != names["v2"]["r1"]
    assert names["v1"]["r3"] != names["v2"]["r3"]


def test_the_workload_check_fails_a_daemonset_that_schedules_nothing() -> None:
    problems = daemonsets_check()["problems"]

    def ds(name: str, desired: int, updated: int, available: int, seen: int = 1) -> dict[str, Any]:
        return {"metadata": {"name": name, "generation": 1},
                "status": {"observedGeneration": seen, "desiredNumberScheduled": desired,
                           "updatedNumberScheduled": updated, "numberAvailable": available}}

    assert problems([ds("driver", 1, 1, 1), ds("discovery-0", 1, 1, 1)]) == []
    assert problems([ds("driver", 1, 1, 1), ds("perception", 0, 0, 0)]) == [
        "perception: schedules no pod: no node has its nodeSelector labels"]
    assert problems([ds("driver", 1, 0, 1)]) == ["driver: not yet updated"]
    assert problems([ds("driver", 1, 1, 0)]) == ["driver: not yet available"]
    assert problems([ds("driver", 1, 1, 1, seen=0)]) == [
        "driver: its change is not yet seen by the DaemonSet controller"]
    assert problems([]) == ["no DaemonSet in the robot's namespace"]


# ---------------------------------------------------------------- what the controllers call ready

NODES = {
    "r1": [{"robocore.dev/host": "main", "kubernetes.io/arch": "amd64"},
           {"robocore.dev/host": "jetson", "kubernetes.io/arch": "arm64"}],
    "r3": [{"robocore.dev/host": "base", "kubernetes.io/arch": "amd64"}],
}


def nodes_of(robot: str, *, unlabelled_jetson: bool = False) -> list[dict[str, str]]:
    """The robot's cluster's nodes with the labels the docs say to set (the jetson's host label missing on demand)."""
    nodes = [dict(n, **{"robocore.dev/robot": robot}) for n in NODES["r3" if robot == "r3" else "r1"]]
    if unlabelled_jetson:
        nodes = [{k: v for k, v in n.items() if k != "robocore.dev/host"} if n["robocore.dev/host"] == "jetson"
                 else n for n in nodes]
    return nodes


def objects(docs: list[dict[str, Any]], nodes: list[dict[str, str]], look: int) -> Objects:
    """What the robot's objects report at its ``look``-th look (0: the first), every pod that is scheduled assumed
    running: the DaemonSets ready when their available pods are as many as they want (none wanted included, as
    kstatus and Argo CD have it: kubernetes-sigs/cli-utils pkg/kstatus/status/core.go, argo-cd
    gitops-engine/pkg/health/health_daemonset.go); the health Job running at the first look, then complete when
    its pod has a node and its workload check passes on the DaemonSets' statuses (the graph probe assumed to
    pass), else failed (its check fails, or its pod waits for a node until the Job's deadline)."""
    def scheduled(pod: dict[str, Any]) -> int:
        return sum(all(node.get(k) == v for k, v in pod["nodeSelector"].items()) for node in nodes)

    statuses = []
    for name, ds in by_kind(docs, "DaemonSet").items():
        n = scheduled(ds["spec"]["template"]["spec"])
        statuses.append({"metadata": {"name": name, "generation": 1},
                         "status": {"observedGeneration": 1, "desiredNumberScheduled": n,
                                    "updatedNumberScheduled": n, "numberAvailable": n}})
    check = daemonsets_check()["problems"]
    jobs = by_kind(docs, "Job").values()
    if not jobs:
        return Objects(workloads=True)
    if look == 0:
        return Objects(workloads=True, job="running")
    passed = all(scheduled(job["spec"]["template"]["spec"]) and not check(statuses) for job in jobs)
    return Objects(workloads=True, job="complete" if passed else "failed")


def ready(docs: list[dict[str, Any]], nodes: list[dict[str, str]]) -> bool:
    """Whether the robot's objects end ready: its workloads, and its Job (if any) completed."""
    settled = objects(docs, nodes, look=1)
    return settled.workloads and settled.job in (None, "complete")


def test_a_robot_with_an_unlabelled_node_is_not_healthy(rendered: Rendered) -> None:
    docs = rendered["v2"]["r2"]
    assert ready(docs, nodes_of("r2"))
    assert not ready(docs, nodes_of("r2", unlabelled_jetson=True))
    without_gate = [d for d in docs if d["kind"] != "Job"]  # negative control: the controllers' own rule
    assert ready(without_gate, nodes_of("r2", unlabelled_jetson=True))


def looking(rendered: Rendered, broken: tuple[str, str] = ("r2", "v2")) -> Any:
    """The agent's view of each robot's objects, look after look; ``broken``: the robot and release whose jetson
    was re-imaged without robocore's labels."""
    looks: dict[tuple[str, str], int] = {}

    def observe(cluster: Cluster, release: str) -> Objects:
        look = looks[cluster.name, release] = looks.get((cluster.name, release), -1) + 1
        nodes = nodes_of(cluster.name, unlabelled_jetson=(cluster.name, release) == broken)
        return objects(rendered[release][cluster.name], nodes, look)
    return observe


def robots_of(fleet_yaml: dict[str, Any]) -> list[Cluster]:
    return targets(fleet_yaml, [Cluster(r, {"robocore.dev/robot": r}) for r in ("r1", "r2", "r3")])


def test_fleet_stops_at_the_robot_whose_node_lost_its_label(work: Path, rendered: Rendered) -> None:
    fleet_yaml = yaml.safe_load((work / "k8s-v2" / "fleet.yaml").read_text())
    clusters = robots_of(fleet_yaml)
    observe = looking(rendered)
    roll_out(fleet_yaml, clusters, "v1", observe)
    assert all(c.ready and c.applied == "v1" for c in clusters)
    assert roll_out(fleet_yaml, clusters, "v2", observe) == [["r1"], ["r2"]]
    assert {c.name: (c.deployment, c.applied, c.ready) for c in clusters} == {
        "r1": ("v2", "v2", True), "r2": ("v2", "v1", False), "r3": ("v1", "v1", True)}
    stripped = {t: {r: [d for d in docs if d["kind"] != "Job"] for r, docs in robots.items()}
                for t, robots in copy.deepcopy(rendered).items()}  # negative control: without the gate, it all passes
    clusters = robots_of(fleet_yaml)
    roll_out(fleet_yaml, clusters, "v1", looking(stripped))
    assert roll_out(fleet_yaml, clusters, "v2", looking(stripped)) == [["r1"], ["r2"], ["r3"]]


def test_fleet_waits_for_the_health_job_to_complete(work: Path, rendered: Rendered) -> None:
    """Fleet's agent reads a started Job as ready (kstatus): only Helm's wait for Jobs holds the next robot until
    the gate has passed. Negative control: the same fleet.yaml without ``helm`` lets r3 go while r2's gate runs."""
    fleet_yaml = yaml.safe_load((work / "k8s-v2" / "fleet.yaml").read_text())
    # the longest Job's deadline (r3's model: timeouts.robot 120 s by default, two steps, a minute to start) + 60 s
    assert fleet_yaml["helm"] == {"timeoutSeconds": 2 * 120 + 60 + 60, "waitForJobs": True}
    without = {k: v for k, v in fleet_yaml.items() if k != "helm"}
    clusters = robots_of(without)
    observe = looking(rendered)
    roll_out(without, clusters, "v1", observe)
    assert roll_out(without, clusters, "v2", observe) == [["r1"], ["r2"], ["r3"]]  # r3 went while r2's gate ran
    assert {c.name: (c.applied, c.ready) for c in clusters} == {
        "r1": ("v2", True), "r2": ("v2", False), "r3": ("v2", True)}  # then r2's gate failed: too late
    for wait in ({"timeoutSeconds": 300}, {"waitForJobs": True}):  # Helm waits for Jobs only with both
        clusters = robots_of(fleet_yaml)
        observe = looking(rendered)
        roll_out({**without, "helm": wait}, clusters, "v1", observe)
        assert roll_out({**without, "helm": wait}, clusters, "v2", observe)[-1] == ["r3"]
