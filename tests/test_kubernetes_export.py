"""robocore export kubernetes on the template's project: golden files, kustomize renders, --strict validation,
byte-identical re-runs, what a robot.yaml change changes, the refusals and the export folder's safety."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import kubernetes_validate
import pytest
import yaml
from golden_files import GOLDEN, check_golden
from k8s_checks import by_kind, render, validate
from template_repo import hide_origin

from robocore.commands import init
from robocore.commands.export import export_kubernetes
from robocore.commands.support.context import Options
from robocore.errors import RobocoreError

TAG = "v1"


@pytest.fixture(scope="module")
def template_project(tmp_path_factory: pytest.TempPathFactory) -> Path:
    with pytest.MonkeyPatch.context() as monkeypatch:
        hide_origin(monkeypatch)
        project = tmp_path_factory.mktemp("k8s") / "myrobot"
        init.run(project, defaults=True, distro=None, base=None, dry_run=False)
        return project


def cli_export(project: Path, folder: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """The command line, as a user runs it (in the project folder)."""
    argv = [sys.executable, "-m", "robocore", "export", "kubernetes", str(folder), *args]
    return subprocess.run(argv, capture_output=True, text=True, timeout=120, cwd=project)


def export(project: Path, folder: Path, tag: str | None = TAG) -> list[str]:
    """The export in this process (what the task runs): the error lines it reports, [] when it wrote."""
    try:
        export_kubernetes(Options(project_dir=project, task="export", quiet=True), folder, tag=tag)
    except RobocoreError as error:
        return error.lines()
    return []


def exported(project: Path, folder: Path, tag: str = TAG) -> dict[str, bytes]:
    assert export(project, folder, tag) == []
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def template_export(template_project: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("out") / "k8s"
    exported(template_project, folder)
    return folder


def copy_project(source: Path, dest: Path) -> Path:
    dest.mkdir(parents=True)
    (dest / "robot.yaml").write_text((source / "robot.yaml").read_text())
    for component in ("talker", "listener"):
        (dest / "components" / component).mkdir(parents=True)
    return dest


# ---------------------------------------------------------------- golden files, render, validate


def test_golden_files_of_the_template(template_export: Path) -> None:
    names = sorted(str(p.relative_to(template_export)) for p in template_export.rglob("*") if p.is_file())
    golden = GOLDEN / "kubernetes" / "template"
    if not os.environ.get("UPDATE_GOLDEN"):
        assert names == sorted(str(p.relative_to(golden)) for p in golden.rglob("*") if p.is_file())
    for name in names:
        check_golden(f"kubernetes/template/{name}", (template_export / name).read_text())


def test_every_overlay_and_the_root_render_and_validate_strict(template_export: Path) -> None:
    overlay = render(template_export / "robots" / "myrobot")
    assert render(template_export) == overlay  # the root lists the one robot
    kinds = sorted(d["kind"] for d in overlay)
    assert kinds == ["ConfigMap", "ConfigMap", "DaemonSet", "DaemonSet", "DaemonSet", "Job", "Namespace", "Role",
                     "RoleBinding", "Service", "ServiceAccount"]
    for doc in overlay:
        assert doc["metadata"].get("namespace", doc["metadata"]["name"]) == "robot-myrobot"
        validate(doc)


def test_pods_are_right_for_ros(template_export: Path) -> None:
    docs = render(template_export / "robots" / "myrobot")
    daemon_sets = by_kind(docs, "DaemonSet")
    service = by_kind(docs, "Service")["discovery-devmachine"]
    dds = next(iter(by_kind(docs, "ConfigMap")))
    for name, ds in daemon_sets.items():
        pod = ds["spec"]["template"]["spec"]
        assert pod["hostNetwork"] is True and pod["dnsPolicy"] == "ClusterFirstWithHostNet"
        assert pod["hostIPC"] is True  # transport: shm (the default)
        assert pod["nodeSelector"] == {"robocore.dev/host": "devmachine", "kubernetes.io/arch": "amd64",
                                       "robocore.dev/robot": "myrobot"}
        assert {(t["key"], t["effect"]) for t in pod["tolerations"]} == {
            ("node.kubernetes.io/unreachable", "NoExecute"), ("node.kubernetes.io/not-ready", "NoExecute")}
        assert all("tolerationSeconds" not in t for t in pod["tolerations"])
        assert ds["spec"]["updateStrategy"]["rollingUpdate"] == {"maxUnavailable": 1, "maxSurge": 0}
        assert ds["spec"]["template"]["metadata"]["labels"]["robocore.dev/robot"] == "myrobot"
        (container,) = pod["containers"]
        env = {e["name"]: e.get("value") for e in container["env"]}
        if name != "discovery-0":  # the one server lists no other, and reads no profile file
            assert env["ROS_DISCOVERY_SERVER"] == "discovery-devmachine:11811"
            assert pod["volumes"][0]["configMap"]["name"] == dds  # the generated ConfigMap, by its hashed name
            assert container["volumeMounts"][0] == {"name": "v0", "mountPath": "/robocore/dds", "readOnly": True}
        else:
            assert pod["volumes"][0]["hostPath"] == {"path": "/var/lib/robocore/myrobot/discovery-0",
                                                     "type": "DirectoryOrCreate"}
        assert container["image"].endswith(f":{TAG}")
        assert not any("hostPath" in v and "install" in v["hostPath"]["path"] for v in pod.get("volumes", []))
    assert daemon_sets["talker"]["spec"]["template"]["spec"]["containers"][0]["image"] == f"myrobot-talker:{TAG}"
    assert service["spec"]["clusterIP"] == "None" and service["spec"]["publishNotReadyAddresses"] is True
    assert service["spec"]["selector"] == {"robocore.dev/role": "discovery", "robocore.dev/host": "devmachine"}
    wait = daemon_sets["talker"]["spec"]["template"]["spec"]["initContainers"][0]
    assert wait["command"][-1] == "discovery-devmachine" and wait["image"] == f"myrobot-base:{TAG}"


def test_a_planted_unknown_field_is_caught(template_export: Path, tmp_path: Path) -> None:
    """Negative control: the same render and --strict check catch a hand edit with an unknown field."""
    folder = tmp_path / "edited"
    for path in template_export.rglob("*"):
        if path.is_file():
            (folder / path.relative_to(template_export)).parent.mkdir(parents=True, exist_ok=True)
            (folder / path.relative_to(template_export)).write_bytes(path.read_bytes())
    talker = folder / "bases" / "myrobot" / "talker.yaml"
    talker.write_text(talker.read_text().replace("      hostNetwork: true\n", "      hostNetwork: true\n"
                                                 "      hostIPCs: true\n"))
    docs = by_kind(render(folder / "robots" / "myrobot"), "DaemonSet")
    validate(docs["listener"])
    with pytest.raises(kubernetes_validate.ValidationError, match="hostIPCs"):
        validate(docs["talker"])


# ---------------------------------------------------------------- determinism and changes


def test_two_runs_give_byte_identical_output(template_project: Path, template_export: Path, tmp_path: Path) -> None:
    first = {str(p.relative_to(template_export)): p.read_bytes() for p in template_export.rglob("*") if p.is_file()}
    assert exported(template_project, tmp_path / "again") == first
    assert exported(template_project, template_export) == first  # over its own earlier export


def changed_files(template_project: Path, tmp_path: Path, edit: Any) -> set[str]:
    project = copy_project(template_project, tmp_path / "myrobot")
    before = exported(project, tmp_path / "before")
    doc = yaml.safe_load((project / "robot.yaml").read_text())
    edit(doc)
    (project / "robot.yaml").write_text(yaml.safe_dump(doc))
    after = exported(project, tmp_path / "after")
    assert set(before) == set(after)
    return {name for name in before if before[name] != after[name]}


def test_a_changed_entrypoint_changes_only_that_component(template_project: Path, tmp_path: Path) -> None:
    def edit(doc: dict[str, Any]) -> None:
        doc["components"][1]["entrypoint"] = "ros2 run demo_listener listener --ros-args -r chatter:=talk"

    # and the health Job's name: a Job's pods cannot change, so any change to the robot is a new Job
    assert changed_files(template_project, tmp_path, edit) == {"bases/myrobot/listener.yaml",
                                                               "bases/myrobot/health.yaml"}


def test_a_changed_domain_changes_every_workload_and_nothing_else(template_project: Path, tmp_path: Path) -> None:
    def edit(doc: dict[str, Any]) -> None:
        doc["ros_domain_id"] = 7

    assert changed_files(template_project, tmp_path, edit) == {
        "bases/myrobot/discovery-0.yaml", "bases/myrobot/listener.yaml", "bases/myrobot/talker.yaml",
        "bases/myrobot/health.yaml"}


def test_udp_transport_drops_host_ipc_and_changes_the_profiles(template_project: Path, tmp_path: Path) -> None:
    def edit(doc: dict[str, Any]) -> None:
        doc["discovery"] = {"transport": "udp"}

    changed = changed_files(template_project, tmp_path, edit)
    assert {"bases/myrobot/talker.yaml", "bases/myrobot/listener.yaml", "bases/myrobot/discovery-0.yaml",
            "bases/myrobot/dds/client.xml"} <= changed
    assert all(name.startswith("bases/myrobot/") for name in changed)
    talker = yaml.safe_load_all((tmp_path / "after" / "bases" / "myrobot" / "talker.yaml").read_text())
    assert "hostIPC" not in next(iter(talker))["spec"]["template"]["spec"]


# ---------------------------------------------------------------- refusals


REFUSED = """\
ros_distro: jazzy
hosts:
  - name: pc
    ip: 10.0.0.2
components:
  - name: cam
    image: example.org/cam:1
    runs_on: pc
    network: bridge
  - name: rviz
    image: example.org/rviz:1
    runs_on: pc
    gui: true
  - name: once
    image: example.org/once:1
    runs_on: pc
    restart: "no"
  - name: logger
    image: example.org/logger:1
    runs_on: pc
    volumes: [bags:/bags, ./maps:/maps:ro]
  - name: serial
    image: example.org/serial:1
    runs_on: pc
    devices: ["/dev/ttyUSB0:/dev/ttyUSB0:r"]
"""


def test_what_cannot_be_expressed_is_refused_one_line_each(tmp_path: Path) -> None:
    project = tmp_path / "refused"
    project.mkdir()
    (project / "robot.yaml").write_text(REFUSED)
    done = cli_export(project, tmp_path / "out", "--tag", TAG)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    lines = done.stderr.splitlines()
    assert [line.split(": ")[0:2] for line in lines] == [
        ["error", "robot.yaml:9"], ["error", "robot.yaml:13"], ["error", "robot.yaml:17"],
        ["error", "robot.yaml:21"], ["error", "robot.yaml:21"], ["error", "robot.yaml:25"]]
    keys = [line.split(": ")[2] for line in lines]
    assert keys == ["components[0].network", "components[1].gui", "components[2].restart", "components[3].volumes[0]",
                    "components[3].volumes[1]", "components[4].devices[0]"]
    assert not (tmp_path / "out").exists()


def test_without_a_tag_it_says_which_release(template_project: Path, tmp_path: Path) -> None:
    assert "needs --tag" in export(template_project, tmp_path / "out", None)[0]
    assert not (tmp_path / "out").exists()


def test_devices_and_gpus_become_privileged_host_paths_and_the_nvidia_runtime(tmp_path: Path) -> None:
    project = tmp_path / "devices"
    project.mkdir()
    (project / "robot.yaml").write_text(
        "ros_distro: jazzy\nregistry: 10.0.0.2:5000\nhosts:\n  - {name: jetson, ip: 10.0.0.3, arch: arm64}\n"
        "components:\n  - {name: cam, image: example.org/cam:1, runs_on: jetson, nvidia: true,\n"
        "     devices: [/dev/video0, '/dev/ttyUSB0:/dev/serial:rwm'], volumes: ['/var/log/cam:/logs']}\n")
    folder = tmp_path / "out"
    exported(project, folder)
    docs = render(folder / "robots" / "devices")
    cam = by_kind(docs, "DaemonSet")["cam"]
    pod = cam["spec"]["template"]["spec"]
    assert pod["runtimeClassName"] == "nvidia" and pod["nodeSelector"]["kubernetes.io/arch"] == "arm64"
    (container,) = pod["containers"]
    assert container["securityContext"] == {"privileged": True}
    assert container["image"] == "example.org/cam:1"
    paths = {m["mountPath"]: v["hostPath"]["path"] for m in container["volumeMounts"] for v in pod["volumes"]
             if v["name"] == m["name"] and "hostPath" in v}
    assert paths == {"/dev/video0": "/dev/video0", "/dev/serial": "/dev/ttyUSB0", "/logs": "/var/log/cam"}
    assert {"name": "NVIDIA_VISIBLE_DEVICES", "value": "all"} in container["env"]
    assert by_kind(docs, "DaemonSet")["discovery-0"]["spec"]["template"]["spec"]["containers"][0]["image"] == (
        f"10.0.0.2:5000/devices-base:{TAG}")
    for doc in docs:
        validate(doc)


# ---------------------------------------------------------------- the export folder


def test_a_folder_of_other_files_is_refused_and_left_alone(template_project: Path, tmp_path: Path) -> None:
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "notes.txt").write_text("mine")
    assert "did not write" in export(template_project, folder)[0]
    assert [p.name for p in folder.iterdir()] == ["notes.txt"]


def test_nothing_is_written_through_a_link(template_project: Path, tmp_path: Path) -> None:
    outside = tmp_path / "outside"
    outside.mkdir()
    folder = tmp_path / "out"
    exported(template_project, folder)
    bases = folder / "bases"
    os.rename(bases, tmp_path / "moved")
    bases.symlink_to(outside)
    assert "symlink" in export(template_project, folder, "v2")[0]
    assert list(outside.iterdir()) == []
    link = tmp_path / "link"
    link.symlink_to(outside)
    assert "symlink" in export(template_project, link)[0]
    assert list(outside.iterdir()) == []


def test_a_later_export_replaces_only_its_own_files(template_project: Path, tmp_path: Path) -> None:
    folder = tmp_path / "out"
    exported(template_project, folder)
    (folder / "README.md").write_text("the fleet repository")
    (folder / "bases" / "myrobot" / "old.yaml").write_text("stale")
    record = folder / ".robocore-written"
    record.write_text(record.read_text() + "bases/myrobot/old.yaml\n../escape\n")
    (tmp_path / "escape").write_text("outside")
    assert export(template_project, folder, "v2") == []
    assert (folder / "README.md").read_text() == "the fleet repository"
    assert not (folder / "bases" / "myrobot" / "old.yaml").exists()
    assert (tmp_path / "escape").read_text() == "outside"
    assert "newTag: v2" in (folder / "robots" / "myrobot" / "kustomization.yaml").read_text()


def test_robot_namespaces_carry_the_pod_security_level_their_pods_need(template_export: Path) -> None:
    """Host network, host IPC and hostPath are refused by the baseline and restricted levels that hardened clusters
    enforce: the namespace says privileged, for enforce, audit and warn."""
    (namespace,) = by_kind(render(template_export / "robots" / "myrobot"), "Namespace").values()
    labels = namespace["metadata"]["labels"]
    assert {labels[f"pod-security.kubernetes.io/{mode}"] for mode in ("enforce", "audit", "warn")} == {"privileged"}


def test_bare_image_names_are_said_with_their_components(template_project: Path, tmp_path: Path) -> None:
    """Without a registry the images are bare names a node reads as Docker Hub's: the export warns, naming the
    components; with a registry it does not."""
    done = cli_export(template_project, tmp_path / "a", "--tag", TAG)
    assert done.returncode == 0, done.stderr
    (line,) = [line for line in done.stderr.splitlines() if "no registry" in line]
    assert line.startswith("warning: myrobot: no registry") and "talker, listener" in line
    assert "Docker Hub" in line and "k3s ctr images import" in line
    project = copy_project(template_project, tmp_path / "withreg")
    (project / "robot.yaml").write_text("registry: 10.0.0.2:5000\n" + (project / "robot.yaml").read_text())
    done = cli_export(project, tmp_path / "b", "--tag", TAG)
    assert done.returncode == 0, done.stderr
    assert "no registry" not in done.stderr


def test_a_component_waits_for_discovery_at_each_start_not_only_at_pod_start(template_export: Path) -> None:
    """The kubelet restarts a crashed container without its pod's init containers: the component's own command waits
    for the discovery names, then execs the component. Run here with sh, as the container would (``$$`` is
    Kubernetes' escape of ``$``): it waits while a name does not resolve, and starts the component once it does."""
    talker = by_kind(render(template_export / "robots" / "myrobot"), "DaemonSet")["talker"]
    (container,) = talker["spec"]["template"]["spec"]["containers"]
    argv = [a.replace("$$", "$") for a in container["command"] + container["args"]]
    assert argv[:2] == ["sh", "-c"] and argv[3:6] == ["robocore-start", "discovery-devmachine", "--"]
    assert argv[6:] == ["/robocore/entrypoint.sh", "ros2", "run", "demo_talker", "talker"]

    def start(*names: str) -> subprocess.CompletedProcess[str] | None:
        try:
            return subprocess.run([*argv[:4], *names, "--", "echo", "started"], capture_output=True, text=True,
                                  timeout=3)
        except subprocess.TimeoutExpired:
            return None  # still waiting

    done = start("localhost")
    assert done is not None and done.stdout == "started\n"
    assert start("localhost", "discovery-nowhere.invalid") is None  # negative control: it waits
