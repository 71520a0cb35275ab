"""``fleet rollout`` says what each robot will pull, from the manifests and what each robot runs (no Docker: a
fake swarm and fake manifests)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import fleet_world
import pytest

from robocore.adapters import docker_hosts, docker_manifest, swarm
from robocore.commands.fleet_bytes import report_bytes
from robocore.commands.fleet_swarm import FleetProject
from robocore.commands.support.reporting import Reporter
from robocore.errors import DockerError
from robocore.plan import naming
from robocore.plan import swarm_services as plan
from robocore.plan.pull_bytes import ImageLayers

FLEET = """\
manager: {ip: 10.0.0.2}
registry: 127.0.0.1:5000
robots:
  - {name: r1, hosts: {main: {ip: 10.1.1.1}}}
  - {name: r2, hosts: {main: {ip: 10.1.2.1}}}
  - {name: r3, hosts: {main: {ip: 10.1.3.1}}}
"""
REG = "127.0.0.1:5000/p-"
V1, V2, BASE = (REG + "talker@sha256:" + "1" * 64, REG + "talker@sha256:" + "2" * 64,
                REG + "base@sha256:" + "b" * 64)
LAYERS = (("b1", 100_000_000), ("colcon", 5_800))
MANIFESTS = {V1: ImageLayers(("c1", 2_800), (*LAYERS, ("talk1", 2_300))),
             V2: ImageLayers(("c2", 2_800), (*LAYERS, ("talk2", 2_316))),
             BASE: ImageLayers(("cb", 1_000), LAYERS[:1])}


class Client:
    def info(self) -> dict[str, Any]:
        return {"RegistryConfig": {}}

    def close(self) -> None:
        pass


@pytest.fixture
def fleet_project(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> FleetProject:
    made = fleet_world.fleet_project(tmp_path / "p", FLEET)
    project = made.project
    running = {"r1": V1, "r2": V2}  # r3 runs nothing of the project yet

    def services(_client: Any, label: str) -> list[swarm.ServiceInfo]:
        assert label == f"{naming.LABEL_PROJECT}={project.name}"
        return [swarm.ServiceInfo(id=r, name=f"p-{r}-talker", labels={plan.LABEL_ROBOT: r, plan.LABEL_IMAGE: image},
                                  image=image, version=1, attrs={}) for r, image in running.items()] + [
            swarm.ServiceInfo(id=f"d{r}", name=f"p-{r}-discovery-0", labels={plan.LABEL_ROBOT: r}, image=BASE,
                              version=1, attrs={}) for r in running]

    monkeypatch.setattr(swarm, "services", services)
    monkeypatch.setattr(docker_hosts, "local_client", lambda timeout=120: Client())
    return made


def test_each_robot_is_told_what_it_pulls_before_the_rollout(fleet_project: FleetProject,
                                                             monkeypatch: pytest.MonkeyPatch,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    asked: list[tuple[str, bool]] = []

    def image_layers(ref: str, *, insecure: bool, timeout: float = 60) -> ImageLayers:
        asked.append((ref, insecure))
        return MANIFESTS[ref]

    monkeypatch.setattr(docker_manifest, "image_layers", image_layers)
    release = plan.Release(version="v2", components={"talker": {"amd64": V2}}, base={"amd64": BASE})
    pulls = report_bytes(object(), fleet_project, release, ["r1", "r2", "r3"], Reporter())  # type: ignore[arg-type]
    assert [(p.robot, p.pull_bytes, p.known) for p in pulls] == [
        ("r1", 2_800 + 2_316, True),  # the new configuration and the changed layer only
        ("r2", 0, True),  # runs it already
        ("r3", 1_000 + 2_800 + 100_000_000 + 5_800 + 2_316, False)]  # the whole
    assert all(insecure for _, insecure in asked)  # a loopback registry is plain HTTP, as for release
    assert len(asked) == len(set(asked))  # each manifest read once
    err = capsys.readouterr().err
    assert "bytes each robot will pull for v2" in err and "r1: 5.1 kB of 100.0 MB" in err
    assert "r3: at most 100.0 MB (runs nothing of it yet)" in err


def test_a_manifest_that_cannot_be_read_leaves_the_bytes_unknown_and_the_rollout_going(
        fleet_project: FleetProject, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    def image_layers(ref: str, *, insecure: bool, timeout: float = 60) -> ImageLayers:
        raise DockerError(f"reading the manifest of {ref} failed: unauthorized")

    monkeypatch.setattr(docker_manifest, "image_layers", image_layers)
    release = plan.Release(version="v2", components={"talker": {"amd64": V2}}, base={"amd64": BASE})
    assert report_bytes(object(), fleet_project, release, ["r1"], Reporter()) == []  # type: ignore[arg-type]
    assert "bytes each robot will pull: unknown (reading the manifest of" in capsys.readouterr().err
