"""The exported fleet as the controllers read it: Rancher Fleet's partition logic (tests/fleet_model.py, a model of
Fleet's own code) rolls the exported fleet.yaml out; fleet.yaml passes the schema of Fleet's own CRDs (vendored in
tests/vendor/fleet) and the ApplicationSet Argo CD's own CRD schema (vendored in tests/vendor/argocd), unknown
fields refused."""

from __future__ import annotations

import base64
import copy
import gzip
import json
from pathlib import Path
from typing import Any

import jsonschema
import pytest
import yaml
from fleet_model import Cluster, roll_out, targets
from test_kubernetes_fleet import AMR, AMR_FLEET, LEGACY, LEGACY_FLEET, write

from robocore.commands.export import export_kubernetes
from robocore.commands.support.context import Options
from robocore.plan.kubernetes.gitops import ETCD_REQUEST_LIMIT, fleet_bundle_bytes

VENDOR = Path(__file__).parent / "vendor" / "argocd" / "applicationset-schema.yaml"
FLEET_VENDOR = Path(__file__).parent / "vendor" / "fleet" / "fleet-yaml-schema.yaml"


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> Path:
    work = tmp_path_factory.mktemp("rollout")
    amr = write(work / "amr", AMR, AMR_FLEET, ("driver", "perception"))
    legacy = write(work / "legacy", LEGACY, LEGACY_FLEET, ("talker",))
    folder = work / "k8s"
    export_kubernetes(Options(project_dir=amr, task="export", quiet=True), folder, tag="v2",
                      git_repo="https://git.example.org/fleet.git", models=[legacy])
    return folder


@pytest.fixture(scope="module")
def fleet_yaml(exported: Path) -> dict[str, Any]:
    doc: dict[str, Any] = yaml.safe_load((exported / "fleet.yaml").read_text())
    return doc


def robot_clusters() -> list[Cluster]:
    """The robots' clusters as the docs say to register them, plus an unrelated cluster of the default group."""
    robots = [Cluster(name, {"robocore.dev/robot": name}) for name in ("r1", "r2", "r3")]
    return [*robots, Cluster("ops", {"env": "ops"}, groups=("default",))]


def installed(fleet_yaml: dict[str, Any], release: str) -> list[Cluster]:
    """The targeted clusters after a first install of ``release``, every robot healthy."""
    clusters = targets(fleet_yaml, robot_clusters())
    roll_out(fleet_yaml, clusters, release, lambda cluster, deployment: True)
    assert [(c.name, c.deployment, c.ready) for c in clusters] == [(n, release, True) for n in ("r1", "r2", "r3")]
    return clusters


# ---------------------------------------------------------------- Rancher Fleet


def test_fleet_targets_every_robot_cluster_and_nothing_else(fleet_yaml: dict[str, Any]) -> None:
    clusters = [*robot_clusters(), Cluster("r9", {"robocore.dev/robot": "r9"})]  # a robot of no export
    assert [c.name for c in targets(fleet_yaml, clusters)] == ["r1", "r2", "r3"]
    without = {k: v for k, v in fleet_yaml.items() if k != "overrideTargets"}  # negative control: the old file
    assert [c.name for c in targets(without, clusters)] == []  # the group "default" only, and it holds no robot


def test_a_healthy_fleet_goes_v1_to_v2_one_robot_at_a_time_in_wave_order(fleet_yaml: dict[str, Any]) -> None:
    clusters = installed(fleet_yaml, "v1")
    steps = roll_out(fleet_yaml, clusters, "v2", lambda cluster, deployment: True)
    assert steps == [["r1"], ["r2"], ["r3"]]  # canary first, then the rest; never two robots changing at once
    assert all(c.deployment == c.applied == "v2" and c.ready for c in clusters)


def test_the_former_strategy_never_updates_a_ready_robot(fleet_yaml: dict[str, Any]) -> None:
    """Negative control: maxUnavailable 0 (bundle and partitions) installs, then never updates."""
    old = copy.deepcopy(fleet_yaml)
    old["rolloutStrategy"]["maxUnavailable"] = 0
    for partition in old["rolloutStrategy"]["partitions"]:
        partition["maxUnavailable"] = 0
    clusters = installed(old, "v1")
    assert roll_out(old, clusters, "v2", lambda cluster, deployment: True) == []
    assert {c.deployment for c in clusters} == {"v1"}


def test_a_canary_never_ready_stops_the_rollout(fleet_yaml: dict[str, Any]) -> None:
    clusters = installed(fleet_yaml, "v1")
    steps = roll_out(fleet_yaml, clusters, "v2", lambda cluster, deployment: cluster.name != "r1" or deployment != "v2")
    assert steps == [["r1"]]
    assert {c.name: c.deployment for c in clusters} == {"r1": "v2", "r2": "v1", "r3": "v1"}


def test_a_robot_of_the_last_wave_never_ready_leaves_the_others_done(fleet_yaml: dict[str, Any]) -> None:
    clusters = installed(fleet_yaml, "v1")
    steps = roll_out(fleet_yaml, clusters, "v2", lambda cluster, deployment: cluster.name != "r2" or deployment != "v2")
    assert steps == [["r1"], ["r2"]]
    assert {c.name: c.deployment for c in clusters} == {"r1": "v2", "r2": "v2", "r3": "v1"}


def test_fleet_yaml_passes_fleets_own_schema(fleet_yaml: dict[str, Any]) -> None:
    """fleet.yaml against the fields of Fleet's own CRDs (vendored in tests/vendor/fleet), unknown fields refused:
    Fleet itself would drop a misspelt key without a word."""
    schema = strict(yaml.safe_load(FLEET_VENDOR.read_text()))
    jsonschema.validate(fleet_yaml, schema)
    for path, key in ((("helm",), "waitForJob"), (("rolloutStrategy",), "maxUnavailablePartition"),
                      (("targetCustomizations", 0), "kustomizeDir")):  # negative controls: misspelt keys
        planted = copy.deepcopy(fleet_yaml)
        node: Any = planted
        for part in path:
            node = node[part]
        node[key] = 1
        with pytest.raises(jsonschema.ValidationError, match=key):
            jsonschema.validate(planted, schema)


# ---------------------------------------------------------------- Argo CD


def strict(schema: Any) -> Any:
    """The CRD's structural schema as the API server applies it with field validation Strict: an object's unknown
    fields refused, unless the schema preserves them."""
    if isinstance(schema, dict):
        out = {k: strict(v) for k, v in schema.items()}
        if out.get("type") == "object" and "properties" in out and "additionalProperties" not in out \
                and not out.get("x-kubernetes-preserve-unknown-fields"):
            out["additionalProperties"] = False
        return out
    if isinstance(schema, list):
        return [strict(v) for v in schema]
    return schema


@pytest.fixture(scope="module")
def application_set_schema() -> Any:
    return strict(yaml.safe_load(VENDOR.read_text()))


def test_the_application_set_passes_argo_cds_own_crd_schema(exported: Path, application_set_schema: Any) -> None:
    text = (exported / "argocd" / "applicationset.yaml").read_text()
    doc = yaml.safe_load(text)
    jsonschema.validate(doc, application_set_schema)
    planted = copy.deepcopy(doc)  # negative controls: an unknown field where robocore writes, and a wrong type
    planted["spec"]["strategy"]["rollingSync"]["steps"][0]["waitFor"] = "healthy"
    with pytest.raises(jsonschema.ValidationError, match="waitFor"):
        jsonschema.validate(planted, application_set_schema)
    planted = copy.deepcopy(doc)
    planted["spec"]["template"]["spec"]["syncPolicy"]["automated"]["prune"] = "yes"
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(planted, application_set_schema)


def test_the_application_set_says_progressive_syncs_must_be_on(exported: Path) -> None:
    head = (exported / "argocd" / "applicationset.yaml").read_text().split("apiVersion:")[0]
    assert 'applicationsetcontroller.enable.progressive.syncs: "true"' in head and "argocd-cmd-params-cm" in head


# ---------------------------------------------------------------- Fleet's Bundle object


def as_fleet_stores_it(files: dict[str, str]) -> int:
    """The JSON of the Bundle's resources and targets as Fleet's bundlereader writes them (read.go, loaddirectory.go):
    plain text up to 1,000,000 bytes, else every file base64 of gzip."""
    doc = yaml.safe_load(files["fleet.yaml"])
    targets = doc["targetCustomizations"] + doc["overrideTargets"]
    spec = {"targets": targets, "targetRestrictions": doc["overrideTargets"], "rolloutStrategy": doc["rolloutStrategy"]}
    plain = [{"name": n, "content": t} for n, t in files.items()]
    if len(json.dumps({"spec": {**spec, "resources": plain}})) < 1_000_000:
        return len(json.dumps({"spec": {**spec, "resources": plain}}))
    packed = [{"name": n, "content": base64.b64encode(gzip.compress(t.encode())).decode(), "encoding": "base64+gz"}
              for n, t in files.items()]
    return len(json.dumps({"spec": {**spec, "resources": packed}}))


def fleet_of(exported: Path, robots: int) -> dict[str, str]:
    """The export's files with r1's overlay copied to ``robots`` robots, and fleet.yaml's targets for each."""
    files = {str(p.relative_to(exported)): p.read_text() for p in exported.rglob("*") if p.is_file()}
    overlay = {n: t for n, t in files.items() if n.startswith("robots/r1/")}
    files = {n: t for n, t in files.items() if not n.startswith("robots/")}
    doc = yaml.safe_load(files["fleet.yaml"])
    custom, names = doc["targetCustomizations"][0], [f"robot-{i}" for i in range(robots)]
    doc["targetCustomizations"] = [{**custom, "name": r, "clusterSelector": {"matchLabels": {"robocore.dev/robot": r}},
                                    "kustomize": {"dir": f"robots/{r}"}} for r in names]
    doc["overrideTargets"][0]["clusterSelector"]["matchExpressions"][0]["values"] = names
    files["fleet.yaml"] = yaml.safe_dump(doc)
    for r in names:
        files.update({n.replace("/r1/", f"/{r}/"): t.replace("r1", r) for n, t in overlay.items()})
    return files


def test_the_fleet_bundles_size_is_counted_as_fleet_stores_it(exported: Path) -> None:
    for robots in (10, 300, 1200):
        files = fleet_of(exported, robots)
        assert fleet_bundle_bytes(files, limit=10**9) == pytest.approx(as_fleet_stores_it(files), rel=0.1)
    small, large = fleet_of(exported, 300), fleet_of(exported, 3000)
    assert fleet_bundle_bytes(small) < ETCD_REQUEST_LIMIT < fleet_bundle_bytes(large)


def test_a_fleet_too_large_for_one_bundle_is_said(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    amr = write(tmp_path / "amr", AMR, AMR_FLEET, ("driver", "perception"))
    options = Options(project_dir=amr, task="export", quiet=True)
    export_kubernetes(options, tmp_path / "a", tag="v2", git_repo="https://git.example.org/fleet.git")
    assert "Bundle" not in capsys.readouterr().err  # negative control: two robots are far below the limit
    monkeypatch.setattr("robocore.commands.export.ETCD_REQUEST_LIMIT", 10_000)
    export_kubernetes(options, tmp_path / "b", tag="v2", git_repo="https://git.example.org/fleet.git")
    (line,) = [line for line in capsys.readouterr().err.splitlines() if "Bundle" in line]
    assert line.startswith("warning: fleet.yaml: Rancher Fleet would hold these 2 robots in one Bundle object")
    assert "etcdserver: request is too large" in line and "split the fleet" in line
