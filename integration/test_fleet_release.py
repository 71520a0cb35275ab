"""release --fleet: self-contained images pushed to Debian's docker-registry and recorded by digest.

The built demo project (its images reused) gets a fleet file and a read-only project volume; ``release --fleet``
pushes each component's image plus its layers (colcon's files, one per ROS package, the project files) and the base,
and writes the release record. Each recorded digest is what the registry serves, those layers are the only ones
added to the code-less image, and the pushed image, run by digest, finds its ROS package through the entrypoint and
holds the project file. Negative control: the code-less component image, run the same way, has neither. A second
release in which only the talker's project file changed gives the listener and the base the digests of the first (a
robot replaces nothing that did not change) and the talker a new one. A one-line change in the talker's node gives a
release whose talker shares every layer but its package's with the release before, and the same tree released again
with nothing of the fleet images left on this machine gives the same digests.
"""

from __future__ import annotations

import gzip
import json
import stat
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
import yaml
from local_registry import manifest, serve_registry

from robocore.commands.fleet_release import load_release_record
from robocore.commands.support.machine import native_arch
from robocore.plan.fleet_release import ReleaseRecord
from robocore.project import Project

if TYPE_CHECKING:
    from conftest import RobocoreCli

TAG = "fv1"
PARAMS = "greeting: from the fleet image\n"
#: Checks one image: the entrypoint sources the install tree it carries (if any); the project file is there.
PROBE = ["/robocore/entrypoint.sh", "sh", "-c",
         'ros2 pkg prefix "$1" && cat /robocore-params/params.yaml', "sh"]


@pytest.fixture(scope="module")
def registry(tmp_path_factory: pytest.TempPathFactory, docker_client: Any) -> Iterator[str]:
    """Debian's docker-registry on this machine's loopback; afterwards this machine's tags under it are removed."""
    with serve_registry(None, tmp_path_factory.mktemp("registry")) as address:
        yield address
    for image in docker_client.images.list():
        for tag in image.tags:
            if tag.startswith(f"{address}/"):
                docker_client.images.remove(tag)


def probe(docker_client: Any, image: str, package: str, name: str) -> tuple[int, str]:
    """Run :data:`PROBE` in ``image`` (a container named ``name``, removed afterwards): exit code and output."""
    container = docker_client.containers.create(image, entrypoint=PROBE, command=[package], name=name,
                                                network_mode="none")
    try:
        container.start()
        code = container.wait(timeout=120)["StatusCode"]
        return code, container.logs().decode(errors="replace")
    finally:
        container.remove(force=True)


def fleet_copy(project_copies: Callable[..., Path], registry: str) -> Path:
    """A copy of the demo project with a fleet file (this module's registry) and a read-only project volume."""
    def edit(data: dict[str, Any]) -> None:
        talker = next(c for c in data["components"] if c["name"] == "talker")
        talker["volumes"] = ["./config:/robocore-params:ro"]

    root = project_copies("fleetrel", edit=edit)
    (root / "config").mkdir()
    (root / "config" / "params.yaml").write_text(PARAMS)
    host = yaml.safe_load((root / "robot.yaml").read_text())["hosts"][0]["name"]
    (root / "fleet.yaml").write_text(f"manager: {{ip: 10.200.0.1}}\nregistry: {registry}\nrobots:\n"
                                     f"  - {{name: r1, hosts: {{{host}: {{ip: 10.200.1.1}}}}}}\n"
                                     f"  - {{name: r2, hosts: {{{host}: {{ip: 10.200.2.1}}}}}}\n")
    return root


def test_release_fleet_pushes_self_contained_images_recorded_by_digest(
        project_copies: Callable[..., Path], registry: str, run_robocore: RobocoreCli, docker_client: Any) -> None:
    root = fleet_copy(project_copies, registry)
    done = run_robocore(root, "release", "--fleet", "--tag", TAG, "--json")
    envelope = json.loads(done.stdout)
    (result,) = [r for r in envelope["results"] if r["kind"] == "fleet_release"]

    project = Project.load(root)
    path = project.releases_dir / f"{TAG}.json"
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    record = load_release_record(project, TAG, project.load_fleet().registry_for(project.robot))
    assert result["components"] == record.components and result["base"] == record.base
    arch = native_arch()
    assert set(record.components) == {"talker", "listener"} and set(record.base) == {arch}

    for component, package in (("talker", "demo_talker"), ("listener", "demo_listener")):
        ref = record.component_ref(component, arch)
        target, digest = ref.split("@")
        repo = target.removeprefix(f"{registry}/")
        served = manifest(registry, repo, digest)  # the registry serves exactly this digest
        codeless = docker_client.images.get(f"{repo}:latest")
        pushed = docker_client.images.get(ref)
        assert served["config"]["digest"] == pushed.id  # the image pushed is the one recorded
        layers, below = pushed.attrs["RootFS"]["Layers"], codeless.attrs["RootFS"]["Layers"]
        assert layers[:len(below)] == below  # the code-less image, plus one layer per ROS package (and project files)
        added = 4 if component == "talker" else 3  # colcon's files, the package's share/ and code, (project files)
        assert len(layers) == len(below) + added
        assert sum(x["size"] for x in served["layers"][-added:]) < 5_000_000  # small: the install tree only
        assert pushed.labels["dev.robocore.component"] == component

        code, output = probe(docker_client, ref, package, f"robocore-it-fleetrel-{component}")
        assert code == (0 if component == "talker" else 1), output  # only talker has the project file
        assert "/robocore/install" in output
        if component == "talker":
            assert output.endswith(PARAMS)
        # negative control: the code-less image (what the single-robot release pushes) has neither
        code, output = probe(docker_client, codeless.id, package, f"robocore-it-fleetrel-{component}-codeless")
        assert code != 0 and "/robocore/install" not in output, output

    base = record.base_ref(arch)
    assert manifest(registry, base.split("@")[0].removeprefix(f"{registry}/"), base.split("@")[1])["config"][
        "digest"] == docker_client.images.get(base).id


def test_a_release_changes_the_digests_of_what_changed_only(project_copies: Callable[..., Path], registry: str,
                                                              run_robocore: RobocoreCli) -> None:
    """A release, then only the talker's project file edited: the next release's listener and base are the
    digests of the first's (same content, same image), the talker's is new (its layer holds the file)."""
    fleet_root = fleet_copy(project_copies, registry)
    run_robocore(fleet_root, "release", "--fleet", "--tag", TAG)
    project = Project.load(fleet_root)
    registry = project.load_fleet().registry_for(project.robot)
    first = load_release_record(project, TAG, registry)
    (fleet_root / "config" / "params.yaml").write_text(PARAMS.replace("fleet image", "next fleet image"))
    run_robocore(fleet_root, "release", "--fleet", "--tag", "fv2")
    second = load_release_record(project, "fv2", registry)
    arch = native_arch()

    def digests(record: ReleaseRecord) -> tuple[str, str, str]:
        refs = (record.component_ref("talker", arch), record.component_ref("listener", arch), record.base_ref(arch))
        talker, listener, base = (ref.split("@")[1] for ref in refs)
        return talker, listener, base

    (talker1, listener1, base1), (talker2, listener2, base2) = digests(first), digests(second)
    assert (listener2, base2) == (listener1, base1)  # nothing changed: the same images, no robot replaces them
    assert talker2 != talker1  # the control: what changed is released


def blob(registry: str, repo: str, digest: str) -> bytes:
    """The blob ``digest`` of ``repo`` as the registry serves it."""
    import urllib.request

    with urllib.request.urlopen(f"http://{registry}/v2/{repo}/blobs/{digest}", timeout=30) as resp:
        return bytes(resp.read())


def layer_names(data: bytes) -> set[str]:
    """The paths a (gzip) layer blob holds."""
    import io
    import tarfile

    with tarfile.open(fileobj=io.BytesIO(data), mode="r:gz") as tar:
        return set(tar.getnames())


def test_a_one_line_change_is_one_new_layer_and_the_same_tree_the_same_digest_without_cache(
        project_copies: Callable[..., Path], registry: str, run_robocore: RobocoreCli, docker_client: Any) -> None:
    """One layer per ROS package, written by robocore: a one-line change in the talker's Python node gives a release
    whose talker image shares every layer but one (the demo_talker package's, which holds the change) with the
    release before it, from the registry's own manifests; the listener and the base keep their digests. The same
    tree released again after this machine's fleet images were removed (no build cache, no layer kept) gives the
    same digests: the layers are reproducible. What a robot on fl1 pulls for fl2 is that layer, the project files'
    layer above it and the image's configuration (the chain rule of :mod:`robocore.plan.pull_bytes`), a few kB of an
    image of hundreds of MB."""
    from robocore.plan.pull_bytes import parse_manifest, pull_bytes

    root = fleet_copy(project_copies, registry)
    run_robocore(root, "release", "--fleet", "--tag", "fl1")
    project = Project.load(root)
    arch = native_arch()
    first = load_release_record(project, "fl1", registry)
    talker_source = root / "components" / "talker" / "src" / "demo_talker" / "demo_talker" / "talker.py"
    text = talker_source.read_text()
    assert 'print(f"Publishing: {msg.data}"' in text
    talker_source.write_text(text.replace('print(f"Publishing: {msg.data}"', 'print(f"Published: {msg.data}"'))
    run_robocore(root, "build", "--component", "talker", "--quiet")
    run_robocore(root, "release", "--fleet", "--tag", "fl2")
    second = load_release_record(project, "fl2", registry)

    def served(record: ReleaseRecord, component: str) -> tuple[str, dict[str, Any]]:
        target, digest = record.component_ref(component, arch).split("@")
        repo = target.removeprefix(f"{registry}/")
        return repo, manifest(registry, repo, digest)

    repo, old = served(first, "talker")
    _, new = served(second, "talker")
    old_layers, new_layers = [x["digest"] for x in old["layers"]], [x["digest"] for x in new["layers"]]
    assert len(old_layers) == len(new_layers)
    changed = [i for i, (a, b) in enumerate(zip(old_layers, new_layers, strict=True)) if a != b]
    assert len(changed) == 1, changed  # one layer of the talker's image changed; every other is shared
    (index,) = changed
    assert index == len(new_layers) - 2  # demo_talker's code: below it its share/, above it the project files
    holds = layer_names(blob(registry, repo, new_layers[index]))
    assert any(name.endswith("/demo_talker/talker.py") for name in holds), sorted(holds)[:20]
    assert all(name.startswith("robocore/install/demo_talker") or name in ("robocore", "robocore/install")
               for name in holds)  # that package's files only
    assert b"Published: " in gzip.decompress(blob(registry, repo, new_layers[index]))
    # the control: the layer below (colcon's files) and the project files' layer are the same blobs
    assert layer_names(blob(registry, repo, new_layers[-1])) >= {"robocore-params/params.yaml"}
    assert served(second, "listener")[1]["config"] == served(first, "listener")[1]["config"]
    assert second.base_ref(arch) == first.base_ref(arch)
    pulled = pull_bytes([parse_manifest(new)], [parse_manifest(old)])
    # the changed layer, the project files' layer above it (the chain rule: a robot's engine pulls every layer above
    # the first it lacks; 174 bytes here) and the configuration
    above = sum(layer["size"] for layer in new["layers"][index:])
    assert pulled == above + new["config"]["size"] and pulled < 20_000, pulled

    # the same tree again, with nothing of the fleet images left on this machine: the same digests
    # (the listener is the same image in both: one reference)
    for ref in {record.component_ref(c, arch) for record in (first, second) for c in ("talker", "listener")}:
        docker_client.images.remove(ref, force=True)
    for image in docker_client.images.list():
        for tag in image.tags:
            if tag.startswith(f"{registry}/") and "-fleet" in tag and "base" not in tag:
                docker_client.images.remove(tag, force=True)
    run_robocore(root, "release", "--fleet", "--tag", "fl3")
    third = load_release_record(project, "fl3", registry)
    assert third.components == second.components  # reproducible, by digest
