"""release --fleet: self-contained images pushed to Debian's docker-registry and recorded by digest.

The built demo project (its images reused) gets a fleet file and a read-only project volume; ``release --fleet``
pushes each component's image plus one layer (install tree, project files) and the base, and writes the release
record. Each recorded digest is what the registry serves, the layer is the only one added to the code-less
image, and the pushed image, run by digest, finds its ROS package through the entrypoint and holds the project
file. Negative control: the code-less component image, run the same way, has neither.
"""

from __future__ import annotations

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


def test_release_fleet_pushes_self_contained_images_recorded_by_digest(
        project_copies: Callable[..., Path], registry: str, run_robocore: RobocoreCli, docker_client: Any) -> None:
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
    done = run_robocore(root, "release", "--fleet", "--tag", TAG, "--json")
    envelope = json.loads(done.stdout)
    (result,) = [r for r in envelope["results"] if r["kind"] == "fleet_release"]

    project = Project.load(root)
    path = project.releases_dir / f"{TAG}.json"
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    record = load_release_record(project, TAG)
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
        layers = pushed.attrs["RootFS"]["Layers"]
        assert layers[:-1] == codeless.attrs["RootFS"]["Layers"]  # the code-less image plus ONE layer
        assert served["layers"][-1]["size"] < 5_000_000  # small: the install tree (and project files) only
        assert pushed.labels["dev.robocore.release"] == TAG

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
