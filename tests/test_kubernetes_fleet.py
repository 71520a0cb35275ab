"""The acceptance fleet on Kubernetes: three robots of two models (one robot.yaml with an arm64 host, one ROS 1
robot with its master), exported, rendered, validated --strict; the controllers' files follow the waves."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import jsonschema
import pytest
import yaml
from k8s_checks import by_kind, render, validate

from robocore.commands.export import export_kubernetes
from robocore.commands.support.context import Options
from robocore.plan.fleet_release import ReleaseRecord

AMR = """\
ros_distro: jazzy
registry: 10.0.0.2:5000
hosts:
  - {name: main, ip: 10.0.0.10}
  - {name: jetson, ip: 10.0.0.11, arch: arm64}
components:
  - {name: driver, folder: driver, runs_on: main, entrypoint: ros2 run driver node}
  - {name: perception, folder: perception, runs_on: jetson, entrypoint: ros2 run perception node, nvidia: true}
"""
AMR_FLEET = """\
engine: kubernetes
robots:
  - name: r1
    labels: {site: lab}
    hosts: {main: {ip: 10.1.0.10}, jetson: {ip: 10.1.0.11}}
  - name: r2
    labels: {site: b}
    ros_domain_id: 7
    hosts: {main: {ip: 10.2.0.10}, jetson: {ip: 10.2.0.11}}
rollout:
  waves:
    - {name: canary, robots: [r1]}
    - {name: rest}
"""
LEGACY = """\
ros_distro: noetic
registry: 10.0.0.2:5000
base: {kind: debian}
hosts:
  - {name: base, ip: 10.3.0.10}
components:
  - {name: talker, folder: talker, runs_on: base, entrypoint: rosrun demo_talker talker}
"""
LEGACY_FLEET = """\
engine: kubernetes
robots:
  - name: r3
    hosts: {base: {ip: 10.3.0.10}}
rollout:
  waves:
    - {name: rest}
"""


def write(root: Path, robot: str, fleet: str, folders: tuple[str, ...]) -> Path:
    root.mkdir(parents=True)
    (root / "robot.yaml").write_text(robot)
    (root / "fleet.yaml").write_text(fleet)
    for folder in folders:
        (root / folder).mkdir()
    return root


@pytest.fixture(scope="module")
def fleet_export(tmp_path_factory: pytest.TempPathFactory) -> Path:
    work = tmp_path_factory.mktemp("fleet")
    amr = write(work / "amr", AMR, AMR_FLEET, ("driver", "perception"))
    legacy = write(work / "legacy", LEGACY, LEGACY_FLEET, ("talker",))
    folder = work / "k8s"
    export_kubernetes(Options(project_dir=amr, task="export", quiet=True), folder, tag="v2",
                      git_repo="https://git.example.org/fleet.git", git_path="robots-k8s", models=[legacy])
    return folder


@pytest.fixture(scope="module")
def rendered(fleet_export: Path) -> dict[str, list[dict[str, Any]]]:
    return {robot: render(fleet_export / "robots" / robot) for robot in ("r1", "r2", "r3")}


def test_the_fleet_exports_one_base_per_model_and_one_overlay_per_robot(fleet_export: Path) -> None:
    assert sorted(p.name for p in (fleet_export / "bases").iterdir()) == ["amr", "legacy"]
    assert sorted(p.name for p in (fleet_export / "robots").iterdir()) == ["r1", "r2", "r3"]
    root = yaml.safe_load((fleet_export / "kustomization.yaml").read_text())
    assert root["resources"] == ["robots/r1", "robots/r2", "robots/r3"]  # wave order: canary, then rest


def test_every_object_of_every_robot_validates_strict(rendered: dict[str, list[dict[str, Any]]]) -> None:
    for robot, docs in rendered.items():
        for doc in docs:
            assert doc["metadata"].get("namespace", doc["metadata"]["name"]) == f"robot-{robot}"
            validate(doc)


def test_the_arm64_host_is_pinned_and_gets_its_image(rendered: dict[str, list[dict[str, Any]]]) -> None:
    for robot in ("r1", "r2"):
        sets = by_kind(rendered[robot], "DaemonSet")
        perception = sets["perception"]["spec"]["template"]["spec"]
        assert perception["nodeSelector"] == {"robocore.dev/host": "jetson", "kubernetes.io/arch": "arm64",
                                              "robocore.dev/robot": robot}
        assert perception["containers"][0]["image"] == "10.0.0.2:5000/amr-perception:v2"
        assert perception["runtimeClassName"] == "nvidia"
        assert sets["driver"]["spec"]["template"]["spec"]["nodeSelector"]["kubernetes.io/arch"] == "amd64"


def test_a_robots_own_domain_and_labels(rendered: dict[str, list[dict[str, Any]]]) -> None:
    def domains(robot: str) -> set[str]:
        return {e["value"] for ds in by_kind(rendered[robot], "DaemonSet").values()
                for e in ds["spec"]["template"]["spec"]["containers"][0]["env"] if e["name"] == "ROS_DOMAIN_ID"}

    assert domains("r1") == {"0"} and domains("r2") == {"7"}
    labels = by_kind(rendered["r2"], "DaemonSet")["driver"]["spec"]["template"]["metadata"]["labels"]
    assert labels["site"] == "b" and labels["robocore.dev/robot"] == "r2"


def test_the_ros1_robot_reaches_its_master_by_the_services_name(rendered: dict[str, list[dict[str, Any]]]) -> None:
    docs = rendered["r3"]
    sets = by_kind(docs, "DaemonSet")
    master = sets["discovery-0"]["spec"]["template"]["spec"]["containers"][0]
    assert master["args"][:3] == ["roscore", "-p", "11311"]
    service = by_kind(docs, "Service")["discovery-base"]
    assert service["spec"]["ports"] == [{"name": "tcp-11311", "port": 11311, "protocol": "TCP"}]
    for name in ("discovery-0", "talker"):
        env = sets[name]["spec"]["template"]["spec"]["containers"][0]["env"]
        assert {"name": "ROS_MASTER_URI", "value": "http://discovery-base:11311"} in env
        assert {"name": "ROS_IP", "valueFrom": {"fieldRef": {"fieldPath": "status.hostIP"}}} in env
        assert not any(e["name"] == "ROS_HOSTNAME" for e in env)
    assert [n.rsplit("-", 1)[0] for n in by_kind(docs, "ConfigMap")] == ["robocore-health"]  # no DDS profiles


# ---------------------------------------------------------------- the controllers' files

#: The fields robocore writes in Rancher Fleet's fleet.yaml, as its reference documents them: robocore's own,
#: narrower schema of what it writes (Fleet's own CRDs' schema is checked in test_kubernetes_rollout.py).
SELECTOR = {"type": "object", "additionalProperties": False, "properties": {
    "matchLabels": {"type": "object", "additionalProperties": {"type": "string"}},
    "matchExpressions": {"type": "array", "items": {"type": "object", "additionalProperties": False,
                                                    "required": ["key", "operator", "values"], "properties": {
                                                        "key": {"type": "string"}, "operator": {"enum": ["In"]},
                                                        "values": {"type": "array", "items": {"type": "string"}}}}}}}
FLEET_SCHEMA = {"type": "object", "additionalProperties": False, "properties": {
    "labels": {"type": "object", "additionalProperties": {"type": "string"}},
    "overrideTargets": {"type": "array", "items": {"type": "object", "additionalProperties": False,
                                                   "required": ["name", "clusterSelector"], "properties": {
        "name": {"type": "string"}, "clusterSelector": SELECTOR}}},
    "targetCustomizations": {"type": "array", "items": {"type": "object", "additionalProperties": False,
                                                        "required": ["name", "clusterSelector"], "properties": {
        "name": {"type": "string"}, "clusterSelector": SELECTOR, "doNotDeploy": {"type": "boolean"},
        "kustomize": {"type": "object", "additionalProperties": False, "properties": {"dir": {"type": "string"}}}}}},
    "helm": {"type": "object", "additionalProperties": False, "properties": {
        "timeoutSeconds": {"type": "integer"}, "waitForJobs": {"type": "boolean"}}},
    "rolloutStrategy": {"type": "object", "additionalProperties": False, "properties": {
        "maxUnavailable": {"type": ["integer", "string"]}, "maxUnavailablePartitions": {"type": ["integer", "string"]},
        "partitions": {"type": "array", "items": {"type": "object", "additionalProperties": False,
                                                  "required": ["name", "clusterSelector"], "properties": {
            "name": {"type": "string"}, "maxUnavailable": {"type": ["integer", "string"]},
            "clusterSelector": SELECTOR}}}}}}}


def test_fleet_partitions_are_the_waves(fleet_export: Path) -> None:
    doc = yaml.safe_load((fleet_export / "fleet.yaml").read_text())
    jsonschema.validate(doc, FLEET_SCHEMA)
    partitions = doc["rolloutStrategy"]["partitions"]
    assert [(p["name"], p["clusterSelector"]["matchExpressions"][0]["values"]) for p in partitions] == [
        ("canary", ["r1"]), ("rest", ["r2", "r3"])]
    dirs = {t["name"]: t.get("kustomize", {}).get("dir") for t in doc["targetCustomizations"]}
    assert dirs == {"r1": "robots/r1", "r2": "robots/r2", "r3": "robots/r3", "not-a-robot": None}
    assert doc["targetCustomizations"][-1] == {"name": "not-a-robot", "clusterSelector": {}, "doNotDeploy": True}
    (override,) = doc["overrideTargets"]  # the robots' clusters, whatever the GitRepo targets
    assert override["clusterSelector"]["matchExpressions"][0]["values"] == ["r1", "r2", "r3"]
    strategy = doc["rolloutStrategy"]  # the gate is the bundle's limit; a partition's 0 would stop every update
    assert (strategy["maxUnavailable"], strategy["maxUnavailablePartitions"]) == (1, 0)
    assert all("maxUnavailable" not in p for p in partitions)
    assert doc["helm"]["waitForJobs"] is True  # the agent's Helm upgrade waits for the health Jobs to complete


def test_argo_rolling_sync_steps_are_the_waves(fleet_export: Path) -> None:
    doc = yaml.safe_load((fleet_export / "argocd" / "applicationset.yaml").read_text())
    assert (doc["apiVersion"], doc["kind"]) == ("argoproj.io/v1alpha1", "ApplicationSet")
    spec = doc["spec"]
    steps = spec["strategy"]["rollingSync"]["steps"]
    assert spec["strategy"]["type"] == "RollingSync"
    assert [s["matchExpressions"][0]["values"] for s in steps] == [["canary"], ["rest"]]
    assert [s["maxUpdate"] for s in steps] == [1, 1]  # one robot at a time within a wave, as with Fleet
    elements = spec["generators"][0]["list"]["elements"]
    assert [(e["robot"], e["wave"], e["path"]) for e in elements] == [
        ("r1", "canary", "robots-k8s/robots/r1"), ("r2", "rest", "robots-k8s/robots/r2"),
        ("r3", "rest", "robots-k8s/robots/r3")]
    template = spec["template"]
    assert template["metadata"]["labels"]["robocore.dev/wave"] == "{{.wave}}"
    assert template["spec"]["source"]["repoURL"] == "https://git.example.org/fleet.git"
    # RollingSync switches automated sync off and syncs itself; it prunes only when the template says prune
    assert template["spec"]["syncPolicy"]["automated"] == {"prune": True}


def test_images_by_digest_per_arch(tmp_path: Path) -> None:
    """What a release record gives (a digest per repository and arch) maps each host's logical image on its own."""
    from robocore.plan.kubernetes import ImageRef, RobotTarget, plan_export
    from robocore.project import Project

    amr = write(tmp_path / "amr", AMR, AMR_FLEET, ("driver", "perception"))
    project = Project.load(amr)

    def digests(repository: str, arch: str) -> ImageRef:
        digit = "a" if arch == "amd64" else "b"
        return ImageRef(name=f"10.0.0.2:5000/{repository}", digest="sha256:" + digit * 64)

    files = plan_export({"amr": project}, [RobotTarget(name="r1", model="amr", wave="all", images=digests)], "amr")
    folder = tmp_path / "out"
    for name, text in files.items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text(text)
    sets = by_kind(render(folder / "robots" / "r1"), "DaemonSet")
    image = {name: ds["spec"]["template"]["spec"]["containers"][0]["image"] for name, ds in sets.items()}
    assert image == {"driver": "10.0.0.2:5000/amr-driver@sha256:" + "a" * 64,
                     "perception": "10.0.0.2:5000/amr-perception@sha256:" + "b" * 64,
                     "discovery-0": "10.0.0.2:5000/amr-base@sha256:" + "a" * 64}
    wait = sets["perception"]["spec"]["template"]["spec"]["initContainers"][0]["image"]
    assert wait == "10.0.0.2:5000/amr-base@sha256:" + "b" * 64  # the base of the jetson's own arch


def test_a_recorded_fleet_release_is_exported_by_digest(tmp_path: Path) -> None:
    """With ``release --fleet``'s record of the tag, every image is its digest for its host's arch."""
    amr = write(tmp_path / "amr", AMR, AMR_FLEET, ("driver", "perception"))
    registry = "10.0.0.2:5000"

    def ref(repo: str, digit: str) -> str:
        return f"{registry}/{repo}@sha256:" + digit * 64

    record = ReleaseRecord(version="v9", registry=registry,
                           components={"driver": {"amd64": ref("amr-driver", "1")},
                                       "perception": {"arm64": ref("amr-perception", "2")}},
                           base={"amd64": ref("amr-base", "3"), "arm64": ref("amr-base", "4")})
    (amr / ".robocore" / "releases").mkdir(parents=True)
    (amr / ".robocore" / "releases" / "v9.json").write_text(record.to_json())
    folder = tmp_path / "out"
    export_kubernetes(Options(project_dir=amr, task="export", quiet=True), folder, tag="v9")
    sets = by_kind(render(folder / "robots" / "r2"), "DaemonSet")
    image = {name: ds["spec"]["template"]["spec"]["containers"][0]["image"] for name, ds in sets.items()}
    assert image == {"driver": ref("amr-driver", "1"), "perception": ref("amr-perception", "2"),
                     "discovery-0": ref("amr-base", "3")}
    for doc in sets.values():
        validate(doc)


VOLUMES = """\
ros_distro: jazzy
registry: 10.0.0.2:5000
hosts: [{name: main, ip: 10.0.0.10}]
components:
  - name: mapper
    folder: mapper
    runs_on: main
    entrypoint: ros2 run mapper node
    volumes: ['./config/maps:/maps:ro', './data:/data', '/var/log/mapper:/logs']
  - {name: viewer, image: 'example.org/viewer:1', runs_on: main, volumes: ['./config/maps:/maps:ro']}
"""
VOLUMES_FLEET = """\
engine: kubernetes
robots:
  - {name: r1, hosts: {main: {ip: 10.1.0.10}}}
"""


def volumes_project(tmp_path: Path, *, recorded: bool) -> Path:
    """A robot whose component has a read-only project volume, a writable one and a host path; with ``recorded``,
    ``release --fleet --tag v9`` recorded its images (which then carry the read-only files)."""
    root = write(tmp_path / "mapbot", VOLUMES, VOLUMES_FLEET, ("mapper", "config", "config/maps"))
    if recorded:
        ref = "10.0.0.2:5000/mapbot-{}@sha256:" + "5" * 64
        record = ReleaseRecord(version="v9", registry="10.0.0.2:5000",
                               components={"mapper": {"amd64": ref.format("mapper")},
                                           "viewer": {"amd64": ref.format("viewer")}},
                               base={"amd64": ref.format("base")})
        (root / ".robocore" / "releases").mkdir(parents=True)
        (root / ".robocore" / "releases" / "v9.json").write_text(record.to_json())
    return root


def test_read_only_project_volumes_come_in_the_fleet_image_and_are_not_mounted(tmp_path: Path) -> None:
    root = volumes_project(tmp_path, recorded=True)
    folder = tmp_path / "out"
    export_kubernetes(Options(project_dir=root, task="export", quiet=True), folder, tag="v9")
    docs = render(folder / "robots" / "r1")
    pod = by_kind(docs, "DaemonSet")["mapper"]["spec"]["template"]["spec"]
    (container,) = pod["containers"]
    assert container["image"] == "10.0.0.2:5000/mapbot-mapper@sha256:" + "5" * 64  # the image that carries /maps
    volumes = {v["name"]: v for v in pod["volumes"]}
    mounted = {m["mountPath"]: volumes[m["name"]] for m in container["volumeMounts"]}
    assert "/maps" not in mounted
    assert mounted["/logs"]["hostPath"] == {"path": "/var/log/mapper"}
    data = mounted["/data"]["hostPath"]  # writable: a folder of the host, under its mount root, made when missing
    assert data["type"] == "DirectoryOrCreate" and data["path"].endswith("/mapper/data")
    assert not any("config/maps" in v.get("hostPath", {}).get("path", "") for v in pod["volumes"])
    viewer = by_kind(docs, "DaemonSet")["viewer"]["spec"]["template"]["spec"]  # robot.yaml's image, extended
    assert viewer["containers"][0]["image"] == "10.0.0.2:5000/mapbot-viewer@sha256:" + "5" * 64
    assert "/maps" not in [m["mountPath"] for m in viewer["containers"][0].get("volumeMounts", [])]
    for doc in docs:
        validate(doc)


def test_read_only_project_volumes_without_a_fleet_release_are_refused_one_line(tmp_path: Path) -> None:
    """Images by tag are code-less: nothing would put the read-only files in the pod. The writable volume is not
    refused."""
    root = volumes_project(tmp_path, recorded=False)
    argv = [sys.executable, "-m", "robocore", "export", "kubernetes", str(tmp_path / "out"), "--tag", "v9"]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=120, cwd=root)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    lines = [line for line in done.stderr.splitlines() if line.startswith("error:")]
    assert [line.split(": ")[1:3] for line in lines] == [["robot.yaml:9", "components[0].volumes[0]"],
                                                         ["robot.yaml:10", "components[1].volumes[0]"]]
    assert all("release --fleet --tag" in line for line in lines)
    assert not (tmp_path / "out").exists()


def cli(project: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """``robocore export kubernetes ARGS`` as a user runs it, in ``project``."""
    argv = [sys.executable, "-m", "robocore", "export", "kubernetes", *args]
    return subprocess.run(argv, capture_output=True, text=True, timeout=120, cwd=project)


def repo_url(folder: Path) -> tuple[str, str]:
    """The ApplicationSet's repoURL and the first robot's path."""
    spec = yaml.safe_load((folder / "argocd" / "applicationset.yaml").read_text())["spec"]
    return spec["template"]["spec"]["source"]["repoURL"], spec["generators"][0]["list"]["elements"][0]["path"]


def test_the_repository_comes_from_fleet_yaml_or_the_option_and_a_placeholder_is_said(tmp_path: Path) -> None:
    gitops = "gitops: {repo: 'git@git.example.org:team/fleet.git', path: k8s}\n"
    amr = write(tmp_path / "amr", AMR, AMR_FLEET + gitops, ("driver", "perception"))
    done = cli(amr, str(tmp_path / "a"), "--tag", "v2")
    assert done.returncode == 0, done.stderr
    assert repo_url(tmp_path / "a") == ("git@git.example.org:team/fleet.git", "k8s/robots/r1")
    assert "placeholder" not in done.stderr
    done = cli(amr, str(tmp_path / "b"), "--tag", "v2", "--git-repo", "https://git.example.org/other.git",
               "--git-path", "fleet")
    assert done.returncode == 0, done.stderr
    assert repo_url(tmp_path / "b") == ("https://git.example.org/other.git", "fleet/robots/r1")
    (amr / "fleet.yaml").write_text(AMR_FLEET)
    done = cli(amr, str(tmp_path / "c"), "--tag", "v2")
    assert done.returncode == 0, done.stderr
    assert repo_url(tmp_path / "c")[0].endswith(".invalid/set-with--git-repo.git")
    (warning,) = [line for line in done.stderr.splitlines() if "applicationset" in line]
    assert warning.startswith("warning: argocd/applicationset.yaml names no git repository (a placeholder")
    assert "--git-repo" in warning


def test_images_by_tag_are_said_to_hold_no_install_tree(tmp_path: Path) -> None:
    """Without a fleet release record the images are the code-less ones of ``release --tag``: the export says
    which components then lack their install tree; with a record it says nothing of the kind."""
    amr = write(tmp_path / "amr", AMR, AMR_FLEET + "gitops: {repo: 'https://git.example.org/f.git'}\n",
                ("driver", "perception"))
    done = cli(amr, str(tmp_path / "a"), "--tag", "v9")
    assert done.returncode == 0, done.stderr
    (warning,) = [line for line in done.stderr.splitlines() if line.startswith("warning:")]
    assert "amr: release v9 has no fleet release record" in warning and "driver, perception" in warning
    assert "release --fleet --tag v9" in warning
    write_amr_release(amr, "v9")
    done = cli(amr, str(tmp_path / "b"), "--tag", "v9")
    assert done.returncode == 0, done.stderr
    assert "warning:" not in done.stderr


def write_amr_release(amr: Path, version: str) -> None:
    """A fleet release record of the amr project (its driver amd64, its perception arm64), by digest."""
    ref = "10.0.0.2:5000/amr-{}@sha256:" + "6" * 64
    record = ReleaseRecord(version=version, registry="10.0.0.2:5000",
                           components={"driver": {"amd64": ref.format("driver")},
                                       "perception": {"arm64": ref.format("perception")}},
                           base={"amd64": ref.format("base"), "arm64": ref.format("base")})
    (amr / ".robocore" / "releases").mkdir(parents=True)
    (amr / ".robocore" / "releases" / f"{version}.json").write_text(record.to_json())


def test_a_bad_repository_option_is_one_line_and_nothing_is_written(tmp_path: Path) -> None:
    amr = write(tmp_path / "amr", AMR, AMR_FLEET, ("driver", "perception"))
    for args, shown in ((("--git-repo", "https://bot:s3cret@git.example.org/f.git"), "must not hold a password"),
                        (("--git-repo", "file:///srv/fleet"), "a GitOps controller clones"),
                        (("--git-path", "../elsewhere"), "no '.' or '..' part")):
        done = cli(amr, str(tmp_path / "out"), "--tag", "v2", *args)
        assert done.returncode == 2 and "Traceback" not in done.stderr
        (line,) = [line for line in done.stderr.splitlines() if line.startswith("error:")]
        assert line.startswith(f"error: {args[0]}: ") and shown in line and "s3cret" not in line
        assert not (tmp_path / "out").exists()


def test_maintenance_windows_are_said_not_to_be_in_the_export(tmp_path: Path) -> None:
    """fleet.yaml's rollout.windows (and the update lock) have no counterpart in Fleet's or Argo CD's files: one
    warning line at the key's line, and the files are those of a fleet without windows."""
    repo = "gitops: {repo: 'https://git.example.org/f.git'}\n"
    windows = "  windows:\n    - {robots: [r1], from: '22:00', to: '06:00', timezone: Europe/Berlin}\n"
    amr = write(tmp_path / "amr", AMR, AMR_FLEET + windows + repo, ("driver", "perception"))
    write_amr_release(amr, "v2")  # a fleet release, so that no other warning comes
    done = cli(amr, str(tmp_path / "a"), "--tag", "v2")
    assert done.returncode == 0, done.stderr
    (warning,) = [line for line in done.stderr.splitlines() if "warning" in line]
    line = AMR_FLEET.count("\n") + 1  # windows: is the line after the fleet file's
    assert warning.startswith(f"fleet.yaml:{line}: rollout.windows: warning: not in the Kubernetes export")
    assert "/robocore/update_lock" in warning
    (amr / "fleet.yaml").write_text(AMR_FLEET + repo)  # negative control: no windows, no warning, the same files
    done = cli(amr, str(tmp_path / "b"), "--tag", "v2")
    assert done.returncode == 0 and "warning" not in done.stderr, done.stderr
    assert [p.read_bytes() for p in sorted((tmp_path / "a").rglob("*")) if p.is_file()] == [
        p.read_bytes() for p in sorted((tmp_path / "b").rglob("*")) if p.is_file()]
