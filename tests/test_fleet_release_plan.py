"""Fleet releases: the layer a component's fleet image adds, the pushes, and the release record (no Docker)."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path, PurePosixPath
from typing import Any

import pytest
from conftest import built_project

from robocore.cli import main
from robocore.commands.fleet_release import load_release_record, plan_for, record_path
from robocore.config.loader import parse_robot_text
from robocore.errors import UnsafePath, UsageError
from robocore.plan.fleet_release import (
    FleetSource,
    LayerFile,
    ReleaseRecord,
    baked_volumes,
    digest_ref,
    fleet_tag,
    is_digest_ref,
    layer_files,
    parse_release_record,
    plan_fleet_release,
)
from robocore.project import Project

DIGEST = "sha256:" + "ab" * 32
ROBOT = """\
ros_distro: jazzy
image_prefix: bot-
registry: 10.0.0.2:5000
hosts:
  - {name: main, ip: 127.0.0.1}
components:
  - name: talker
    folder: components/talker
    runs_on: main
    volumes: ["./config/params:/params:ro", "./data:/data", "logs:/logs", "/etc/hosts:/h:ro"]
  - {name: listener, folder: components/listener, runs_on: main}
  - {name: prebuilt, image: "ros:jazzy-ros-base", runs_on: main}
"""
FLEET = "manager: {ip: 10.0.0.2}\nrobots:\n  - {name: r1, hosts: {main: {ip: 10.0.1.5}}}\n"


def test_the_layer_holds_the_install_tree_and_the_read_only_project_files_only(tmp_path: Path) -> None:
    robot = parse_robot_text(ROBOT)
    talker = robot.component("talker")
    files = layer_files(talker, tmp_path / "install", tmp_path)
    assert files == (LayerFile(tmp_path / "install", PurePosixPath("/robocore/install")),
                     LayerFile(tmp_path / "config/params", PurePosixPath("/params")))
    assert baked_volumes(talker) == ("./config/params:/params:ro",)  # ./data (writable) stays a host folder
    assert layer_files(robot.component("prebuilt"), None, tmp_path) == ()


def test_the_plan_tags_every_image_per_arch_and_labels_layered_ones() -> None:
    layer = (LayerFile(Path("/i"), PurePosixPath("/robocore/install")),)
    plan = plan_fleet_release("10.0.0.2:5000/", "v1.2", [
        FleetSource("", "amd64", "bot-base:amd64", "bot-base"),
        FleetSource("talker", "arm64", "bot-talker:latest", "bot-talker", layer),
        FleetSource("prebuilt", "amd64", "ros:jazzy-ros-base", "bot-prebuilt"),
    ])
    assert [(i.component, i.ref, i.is_base, bool(i.layer)) for i in plan.images] == [
        ("", "10.0.0.2:5000/bot-base:v1.2-amd64-fleet", True, False),
        ("talker", "10.0.0.2:5000/bot-talker:v1.2-arm64-fleet", False, True),
        ("prebuilt", "10.0.0.2:5000/bot-prebuilt:v1.2-amd64-fleet", False, False),
    ]
    assert plan.images[1].labels == {"dev.robocore.component": "talker"}  # no release: same content, same digest
    assert plan.images[2].labels == {}
    with pytest.raises(UsageError, match="not a version a fleet release can take"):
        fleet_tag("v" * 120, "amd64")


def test_plan_for_a_project_checks_its_files(tmp_path: Path) -> None:
    project = built_project(tmp_path / "p", ROBOT, components=("talker", "listener"))
    with pytest.raises(UsageError, match=r"volumes\[0\]: .*config/params does not exist"):
        plan_for(project, "v1", "10.0.0.2:5000")
    (project.root / "config" / "params").mkdir(parents=True)
    plan = plan_for(project, "v1", "10.0.0.2:5000")
    assert [(i.component, i.source, [str(f.target) for f in i.layer]) for i in plan.images] == [
        ("", "bot-base:latest" if "latest" in plan.images[0].source else plan.images[0].source, []),
        ("talker", "bot-talker:latest", ["/robocore/install", "/params"]),
        ("listener", "bot-listener:latest", ["/robocore/install"]),
        ("prebuilt", "ros:jazzy-ros-base", []),
    ]
    (project.root / "config" / "params" / "leak").symlink_to("/etc/passwd")
    with pytest.raises(UnsafePath, match=r"leads out|outside"):
        plan_for(project, "v1", "10.0.0.2:5000")


def test_release_fleet_dry_run_says_what_it_would_push_and_writes_nothing(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    project = built_project(tmp_path / "p", ROBOT.replace('"./config/params:/params:ro", ', ""),
                            components=("talker", "listener"))
    (project.root / "fleet.yaml").write_text(FLEET)
    monkeypatch.setenv("DOCKER_HOST", f"unix://{tmp_path}/no-docker.sock")
    monkeypatch.setattr(sys, "argv", ["robocore", "-p", str(project.root), "release", "--fleet", "--tag", "v1",
                                      "--dry-run"])
    main(["-p", str(project.root), "release", "--fleet", "--tag", "v1", "--dry-run"])  # no SystemExit: success
    out = capsys.readouterr().out
    assert ("10.0.0.2:5000/bot-talker:v1-amd64-fleet (amd64): bot-talker:latest + 1 layer(s): install tree "
            "/robocore/install\n") in out
    assert "10.0.0.2:5000/bot-prebuilt:v1-amd64-fleet (amd64): ros:jazzy-ros-base" in out
    assert not project.releases_dir.exists()


def test_release_fleet_refuses_what_swarm_cannot_run_before_anything(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    project = built_project(tmp_path / "p", ROBOT.replace("runs_on: main\n    volumes", "runs_on: main\n"
                                                          "    devices: [/dev/ttyUSB0]\n    volumes"),
                            components=("talker", "listener"))
    (project.root / "fleet.yaml").write_text(FLEET)
    monkeypatch.setenv("DOCKER_HOST", f"unix://{tmp_path}/no-docker.sock")
    monkeypatch.chdir(project.root)
    monkeypatch.setattr(sys, "argv", ["robocore", "release", "--fleet", "--tag", "v1"])
    with pytest.raises(SystemExit) as done:
        main(["release", "--fleet", "--tag", "v1"])
    err = capsys.readouterr().err
    assert done.value.code == 2
    assert err.splitlines() == ["error: robot.yaml:10: components[0].devices: component 'talker' needs devices, "
                                "which Docker Swarm services cannot have; a Swarm fleet refuses it (run it with "
                                "robocore run on each robot)"]
    assert not project.releases_dir.exists()


# --------------------------------------------------------------------------- the record


def record() -> ReleaseRecord:
    return ReleaseRecord(version="v1", registry="10.0.0.2:5000",
                         components={"talker": {"amd64": f"10.0.0.2:5000/bot-talker@{DIGEST}"}},
                         base={"amd64": f"10.0.0.2:5000/bot-base@{DIGEST}"})


def test_the_record_round_trips_and_answers_by_component_and_arch() -> None:
    again = parse_release_record(record().to_json(), "v1.json")
    assert again == record()
    assert again.component_ref("talker", "amd64") == f"10.0.0.2:5000/bot-talker@{DIGEST}"
    assert again.base_ref("amd64") == f"10.0.0.2:5000/bot-base@{DIGEST}"
    with pytest.raises(UsageError, match=r"no image of component 'talker' for arm64 \(it has: talker/amd64\)"):
        again.component_ref("talker", "arm64")
    with pytest.raises(UsageError, match="no base image for arm64"):
        again.base_ref("arm64")
    assert digest_ref("r.lan:5000/x", DIGEST) == f"r.lan:5000/x@{DIGEST}"
    with pytest.raises(ValueError):
        digest_ref("r.lan:5000/x:tag", DIGEST)


@pytest.mark.parametrize("text, why", [
    ("{", "not JSON"),
    ("[]", "format"),
    (json.dumps({"format": 2}), "format 2"),
    (record().to_json().replace(f"@{DIGEST}", ":v1"), "digest reference"),
    (record().to_json().replace("10.0.0.2:5000/bot-talker", "-oProxyCommand=x"), "digest reference"),
    (record().to_json().replace('"v1"', '"-v"'), "version"),
    ('{"format": 1, "version": "v1", "registry": "r", "components": {"a": "x"}, "base": {}}', "digest reference"),
    ("[" * 100_000, "nested too deeply"),
])
def test_a_bad_record_is_refused_whole(text: str, why: str) -> None:
    with pytest.raises(UsageError, match=why) as caught:
        parse_release_record(text, ".robocore/releases/v1.json")
    assert caught.value.message.startswith(".robocore/releases/v1.json: not a release record: ")


def test_load_release_record_reads_only_a_regular_file_inside_the_project(tmp_path: Path) -> None:
    project = Project(root=tmp_path, robot=parse_robot_text(ROBOT))
    with pytest.raises(UsageError, match="no fleet release v1"):
        load_release_record(project, "v1", "10.0.0.2:5000")
    path = record_path(project, "v1")
    path.parent.mkdir(parents=True)
    outside = tmp_path.parent / f"{tmp_path.name}-outside.json"
    outside.write_text(record().to_json())
    path.symlink_to(outside)
    with pytest.raises(UsageError, match="a symlink"):
        load_release_record(project, "v1", "10.0.0.2:5000")
    path.unlink()
    os.mkfifo(path)
    with pytest.raises(UsageError, match="not a regular file"):
        load_release_record(project, "v1", "10.0.0.2:5000")
    path.unlink()
    path.write_text(record().to_json())
    path.chmod(0o600)
    assert load_release_record(project, "v1", "10.0.0.2:5000") == record()
    with pytest.raises(UsageError, match="not a release version"):
        record_path(project, "../x")
    assert is_digest_ref(record().base["amd64"])


def test_a_long_push_says_how_far_it_is_every_few_seconds(monkeypatch: pytest.MonkeyPatch) -> None:
    """Two layers pushed over 12 (fake) seconds: a line every 5 s with the megabytes sent of the layers' sizes; a
    push faster than that says nothing (the negative control)."""
    import time

    from robocore.adapters import image_delivery

    now = [0.0]
    monkeypatch.setattr(time, "monotonic", lambda: now[0])

    def events(seconds: float) -> Any:
        for step in range(1, 13):
            now[0] += seconds / 12
            yield {"status": "Pushing", "id": "a", "progressDetail": {"current": step * 1_000_000,
                                                                     "total": 12_000_000}}
            yield {"status": "Pushing", "id": "b", "progressDetail": {"current": 500_000, "total": 3_000_000}}
        yield {"aux": {"Digest": "sha256:" + "c" * 64}}

    class Client:
        def __init__(self, seconds: float) -> None:
            self.images, self.seconds = self, seconds

        def push(self, *_: Any, **__: Any) -> Any:
            return events(self.seconds)

    said: list[str] = []
    digest = image_delivery.push_digest(Client(12.0), "reg:5000/p-talker", "v2", said.append)  # type: ignore[arg-type]
    assert digest == "sha256:" + "c" * 64
    assert said == ["pushing reg:5000/p-talker:v2: 5.5 of 15.0 MB sent",
                    "pushing reg:5000/p-talker:v2: 10.5 of 15.0 MB sent"], said
    said.clear()
    image_delivery.push_digest(Client(3.0), "reg:5000/p-talker", "v2", said.append)  # type: ignore[arg-type]
    assert said == []
