"""Per-host compose files: golden files (UPDATE_GOLDEN=1 rewrites them) and what write_compose_files writes."""

from __future__ import annotations

import stat
from pathlib import Path
from typing import Any

import pytest
import yaml
from golden_files import check_golden

from robocore.commands.support.composefiles import write_compose_files
from robocore.config.model import Robot
from robocore.files import WRITTEN_RECORD
from robocore.plan import compose, containers, yaml_text
from robocore.plan.discovery import fastdds
from robocore.project import Project

CASES: dict[str, dict[str, Any]] = {
    "jazzy-two-hosts": {
        "ros_distro": "jazzy",
        "hosts": [
            {"name": "dev", "ip": "192.168.1.10", "docker": "local"},
            {"name": "pi", "ip": "192.168.1.20", "user": "pi"},
        ],
        "components": [
            {"name": "talker", "runs_on": "dev", "folder": "components/talker",
             "entrypoint": "ros2 run demo_talker talker"},
            {"name": "listener", "runs_on": "pi", "folder": "components/listener",
             "entrypoint": "ros2 run demo_listener listener", "environment": {"LOG_LEVEL": "info"}},
            {"name": "vnc", "runs_on": "pi", "image": "ghcr.io/example/desktop:jazzy", "ports": ["6080:80"]},
        ],
    },
    "kilted-redundant-udp": {
        "ros_distro": "kilted",
        "ros_domain_id": 42,
        "image_prefix": "acme/bot-",
        "discovery": {"servers": [{"host": "ipc"}, {"host": "jetson", "port": 11900}], "transport": "udp"},
        "hosts": [
            {"name": "ipc", "ip": "10.1.0.2", "user": "robot", "mount_root": "/opt/robot"},
            {"name": "jetson", "ip": "10.1.0.3", "arch": "arm64"},
        ],
        "components": [
            {"name": "driver", "runs_on": "ipc", "folder": "driver", "entrypoint": "ros2 launch driver all.launch.py",
             "launch_args": "use_sim:=false", "devices": ["/dev/ttyUSB0"], "privileged": True, "restart": "always",
             "volumes": ["./maps:/maps:ro", "bags:/bags"]},
            {"name": "perception", "runs_on": "jetson", "folder": "perception", "nvidia": True,
             "entrypoint": "ros2 run perception detector", "restart": "no"},
        ],
    },
    # a robot with no x86 computer (one Jetson), on the official base: its Fast DDS server runs the arm64 base
    "jazzy-official-arm64-only": {
        "ros_distro": "jazzy",
        "base": {"kind": "official"},
        "hosts": [{"name": "jetson", "ip": "10.1.0.3", "arch": "arm64"}],
        "components": [
            {"name": "talker", "runs_on": "jetson", "folder": "components/talker",
             "entrypoint": "ros2 run demo_talker talker"},
        ],
    },
}


def make(case: str, root: Path = Path("/srv/myrobot")) -> Project:
    return Project(root=root, robot=Robot.model_validate(CASES[case]), native_arch="amd64")


@pytest.mark.parametrize("case", sorted(CASES))
def test_golden(case: str) -> None:
    project = make(case)
    for host in project.robot.hosts:
        check_golden(f"compose/{case}-{host.name}.yaml", compose.render(project, host.name))


@pytest.mark.parametrize("case", sorted(CASES))
def test_compose_matches_the_specs(case: str) -> None:
    project = make(case)
    for host in project.robot.hosts:
        document = yaml.safe_load(compose.render(project, host.name))
        specs = containers.host_specs(project, host.name)
        assert specs, f"{host.name} runs nothing: there would be nothing to compare"
        assert list(document["services"]) == [s.service for s in specs]
        for spec in specs:
            service = document["services"][spec.service]
            assert service["labels"]["dev.robocore.spec"] == spec.spec_hash
            assert {k: v.replace("$$", "$") for k, v in service["environment"].items()} == spec.env
            assert [a.replace("$$", "$") for a in service.get("command", [])] == list(spec.command or [])
            assert service.get("depends_on", []) == list(spec.depends_on)
            assert set(spec.depends_on) <= set(document["services"])  # dependencies are on the same host
        named = {m.source for s in specs for m in s.mounts if m.is_named_volume}
        assert set(document.get("volumes", {})) == named


def test_discovery_server_is_in_its_hosts_file_only() -> None:
    project = make("kilted-redundant-udp")
    ipc = yaml.safe_load(compose.render(project, "ipc"))["services"]
    jetson = yaml.safe_load(compose.render(project, "jetson"))["services"]
    assert "discovery-0" in ipc and "discovery-1" not in ipc
    assert "discovery-1" in jetson and "discovery-0" not in jetson
    assert jetson["discovery-1"]["command"][4:] == ["fastdds", "discovery", "-l", "0.0.0.0", "-p", "11900",
                                                    "-x", fastdds.DISCOVERY_PROFILE]
    assert jetson["perception"]["depends_on"] == ["discovery-1"]
    assert ipc["driver"]["environment"]["ROS_DISCOVERY_SERVER"] == "10.1.0.2:11811;10.1.0.3:11900"


def test_write_compose_files(tmp_path: Path) -> None:
    project = make("jazzy-two-hosts", root=tmp_path)
    stale = project.compose_file("old-host")
    stale.parent.mkdir(parents=True)
    stale.write_text("services: {}\n")
    (stale.parent / WRITTEN_RECORD).write_text("old-host.yaml\n")  # robocore wrote it before
    mine = project.compose_file("mine")
    mine.write_text("services: {}\n")  # robocore never wrote this one: it stays
    paths = write_compose_files(project)
    assert [p.name for p in paths] == ["dev.yaml", "pi.yaml"]
    assert not stale.exists() and mine.exists()
    assert stat.S_IMODE(stale.parent.stat().st_mode) == 0o700  # it holds 0600 files
    assert paths[0].read_text() == compose.render(project, "dev")
    profile = tmp_path / ".robocore" / "dds" / "super_client.xml"
    assert "SUPER_CLIENT" in profile.read_text()
    before = paths[0].stat().st_mtime_ns
    write_compose_files(project)  # unchanged: not rewritten
    assert paths[0].stat().st_mtime_ns == before


@pytest.mark.parametrize("case", sorted(CASES))
def test_the_written_text_is_pyyamls_and_the_spec_hash_is_asdicts(case: str) -> None:
    """The fast paths of a 10,000-component compose file change no byte and no container's hash: the text is
    what PyYAML's emitters (libyaml's and the pure-Python one) write, the hash what dataclasses.asdict gives."""
    import dataclasses
    import hashlib
    import json

    project = make(case)
    for host in project.robot.hosts:
        specs = containers.host_specs(project, host.name)
        document = compose.compose_document(specs)
        body = compose.render(project, host.name).split("\n", 3)[3]  # after the 3 header lines
        for dumper in {yaml_text.DUMPER, yaml.SafeDumper}:
            assert body == yaml.dump(document, Dumper=dumper, sort_keys=False, default_flow_style=False, width=120)
        for spec in specs:
            data = dataclasses.asdict(spec)
            if not data["extra_hosts"]:
                del data["extra_hosts"]
            if data["limits"] is None:  # absent, as before robot.yaml had resources
                del data["limits"]
            payload = json.dumps(data, sort_keys=True, separators=(",", ":"))
            assert spec.spec_hash == hashlib.sha256(payload.encode()).hexdigest()[:16]
