"""robocore.plan.containers and run's pure decisions: specs, docker-py kwargs, compose services."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from robocore.config.model import Robot, read_only_project_path
from robocore.plan import containers, naming
from robocore.plan.actions import Action, Existing, decide
from robocore.plan.containers import ContainerSpec, component_spec, discovery_spec, docker_ports, host_specs
from robocore.plan.discovery import fastdds as dds
from robocore.plan.discovery import server_script

ROOT = Path("/srv/myrobot")


def project(**overrides: Any) -> Any:
    from robocore.project import Project

    data: dict[str, Any] = {
        "ros_distro": "jazzy",
        "ros_domain_id": 3,
        "hosts": [
            {"name": "dev", "ip": "192.168.1.10", "docker": "local"},
            {"name": "pi", "ip": "192.168.1.20", "user": "pi"},
        ],
        "components": [
            {"name": "talker", "runs_on": "dev", "folder": "components/talker",
             "entrypoint": "ros2 run demo_talker talker", "launch_args": "--ros-args -p rate:=2"},
            {"name": "cam", "runs_on": "pi", "folder": "components/cam"},
            {"name": "web", "runs_on": "pi", "image": "nginx:1.25", "ports": ["8080:80"]},
        ],
    }
    for key, value in overrides.items():
        data[key] = value
    return Project(root=ROOT, robot=Robot.model_validate(data))


def components_with(**changes: Any) -> list[dict[str, Any]]:
    """The default components, the talker with ``changes``."""
    comps = project().robot.model_dump(mode="json", exclude_defaults=True)["components"]
    comps[0].update(changes)
    return comps


def talker(**changes: Any) -> ContainerSpec:
    p = project(components=components_with(**changes))
    return component_spec(p, p.robot.component("talker"))


# ------------------------------------------------------------------ specs


def test_component_defaults() -> None:
    spec = talker()
    assert spec.name == "myrobot-talker"
    assert spec.image == "myrobot-talker:latest"
    assert spec.entrypoint == (naming.ENTRYPOINT,)
    assert spec.command == ("ros2", "run", "demo_talker", "talker", "--ros-args", "-p", "rate:=2")
    assert spec.network_mode == "host"
    assert spec.ipc_mode == "host"  # default transport shm: same-host containers share memory
    assert spec.restart == "unless-stopped"
    assert not spec.privileged and not spec.gpus
    assert spec.depends_on == ("discovery-0",)  # the default server runs on the first host: dev
    env = spec.env
    assert env["ROS_DISCOVERY_SERVER"] == "192.168.1.10:11811"
    assert env["ROS_DOMAIN_ID"] == "3"


def test_depends_on_the_discovery_server_of_its_host() -> None:
    p = project(discovery={"servers": [{"host": "pi"}]})
    assert [s.service for s in host_specs(p, "dev")] == ["talker"]
    assert component_spec(p, p.robot.component("talker")).depends_on == ()
    pi = host_specs(p, "pi")
    assert [s.service for s in pi] == ["discovery-0", "cam", "web"]
    assert [s.depends_on for s in pi[1:]] == [("discovery-0",), ("discovery-0",)]


def test_udp_transport_has_private_ipc() -> None:
    p = project(discovery={"transport": "udp"})
    spec = component_spec(p, p.robot.component("talker"))
    assert spec.ipc_mode is None
    assert spec.env["FASTDDS_BUILTIN_TRANSPORTS"] == "UDPv4"
    assert "ipc_mode" not in spec.docker_kwargs()
    assert "ipc" not in spec.compose_service()


def test_local_and_remote_mounts() -> None:
    p = project()
    local = component_spec(p, p.robot.component("talker"))
    assert [(m.source, m.target, m.read_only) for m in local.mounts] == [
        (str(ROOT / ".robocore/build/talker/install"), "/robocore/install", True),
        (str(ROOT / ".robocore/dds"), "/robocore/dds", True),
    ]
    remote = component_spec(p, p.robot.component("cam"))
    assert [m.source for m in remote.mounts] == [
        "/home/pi/robocore/cam/current/install",
        "/home/pi/robocore/cam/current/dds",
    ]


def test_project_volumes_on_remote_hosts_come_with_the_release() -> None:
    volumes = ["./config/params:/params:ro", "./data:/data", "/dev/shm:/dev/shm", "maps:/maps:ro"]
    comps = project().robot.model_dump(mode="json", exclude_defaults=True)["components"]
    comps[0]["volumes"] = comps[1]["volumes"] = volumes
    p = project(components=comps)
    remote = {m.target: m for m in component_spec(p, p.robot.component("cam")).mounts}
    # read-only project files: synced with each release; writable: a folder of the robot sync never touches
    assert (remote["/params"].source, remote["/params"].read_only) == (
        "/home/pi/robocore/cam/current/files/config/params", True)
    assert remote["/data"].source == "/home/pi/robocore/cam/data" and not remote["/data"].read_only
    assert remote["/dev/shm"].source == "/dev/shm" and remote["/maps"].source == "maps"  # absolute, named
    local = {m.target: m.source for m in component_spec(p, p.robot.component("talker")).mounts}
    assert local["/params"] == str(ROOT / "config/params") and local["/data"] == str(ROOT / "data")
    assert [read_only_project_path(v) for v in volumes] == ["config/params", None, None, None]


def test_user_settings_reach_the_container() -> None:
    spec = talker(environment={"ROS_DOMAIN_ID": "9", "LEVEL": 3}, devices=["/dev/ttyUSB0:/dev/ttyACM0:rw"],
                  volumes=["./maps:/maps:ro", "/data:/data", "cache:/cache"], privileged=True, nvidia=True,
                  restart="on-failure")
    env = spec.env
    assert env["LEVEL"] == "3"
    assert env["ROS_DOMAIN_ID"] == "9"  # the user's value wins
    kwargs = spec.docker_kwargs()
    assert kwargs["devices"] == ["/dev/ttyUSB0:/dev/ttyACM0:rw"]
    assert kwargs["privileged"] is True
    assert kwargs["restart_policy"] == {"Name": "on-failure"}
    mounts = {m["Target"]: m for m in kwargs["mounts"]}
    assert mounts["/maps"]["Source"] == str(ROOT / "maps") and mounts["/maps"]["ReadOnly"] is True
    assert mounts["/maps"]["Type"] == "bind"
    assert mounts["/cache"]["Type"] == "volume"
    assert mounts["/data"]["ReadOnly"] is False
    request = kwargs["device_requests"][0]
    assert request["Driver"] == "nvidia" and request["Count"] == -1 and request["Capabilities"] == [["gpu"]]
    service = spec.compose_service()
    assert service["privileged"] is True
    assert service["deploy"]["resources"]["reservations"]["devices"][0]["capabilities"] == ["gpu"]


def test_privileged_and_gpus_only_when_asked() -> None:
    kwargs = talker().docker_kwargs()
    assert kwargs["privileged"] is False
    assert "device_requests" not in kwargs
    assert "privileged" not in talker().compose_service()


def test_ports_only_on_bridge() -> None:
    p = project()
    web = component_spec(p, p.robot.component("web"))
    assert web.network_mode == "bridge"  # ports given, no network: bridge
    assert web.ports == ("8080:80",)
    assert web.ipc_mode is None
    assert web.entrypoint is None and web.command is None  # an image: component runs its own command
    assert web.image == "nginx:1.25"
    host_net = talker(ports=["8080:80"], network="host")
    assert host_net.ports == ()
    assert "ports" not in host_net.docker_kwargs()


def test_docker_ports() -> None:
    assert docker_ports(("8080:80",)) == {"80/tcp": 8080}
    assert docker_ports(("127.0.0.1:9000-9001:7000-7001/udp",)) == {
        "7000/udp": ("127.0.0.1", 9000),
        "7001/udp": ("127.0.0.1", 9001),
    }
    with pytest.raises(ValueError):
        docker_ports(("1-3:1-2",))


def test_no_entrypoint_idles() -> None:
    p = project()
    assert component_spec(p, p.robot.component("cam")).command == containers.IDLE_COMMAND


def test_discovery_spec() -> None:
    p = project(discovery={"servers": [{"host": "pi", "port": 12000}, {"host": "dev"}]})
    spec = discovery_spec(p, 0)
    assert spec.host == "pi"
    assert spec.name == "myrobot-discovery-0"
    assert spec.image == "myrobot-base:latest"
    assert spec.entrypoint == (naming.ENTRYPOINT,)
    assert spec.command is not None
    assert spec.command[:2] == ("sh", "-c") and spec.command[2] == dds.DISCOVERY_SCRIPT
    assert spec.command[4:] == ("fastdds", "discovery", "-i", "0", "-l", "0.0.0.0", "-p", "12000",
                                "-x", dds.DISCOVERY_PROFILE)
    assert spec.env["ROBOCORE_DS_HOLD"] == str(dds.restart_hold_seconds(p.robot))
    assert spec.env["ROBOCORE_DS_XML"] == dds.server_profile_xml(p.robot)
    assert [(m.source, m.target) for m in spec.mounts] == [("myrobot-discovery-0-state", dds.DISCOVERY_STATE)]
    assert spec.network_mode == "host"
    assert spec.labels[naming.LABEL_ROLE] == "discovery"
    assert spec.env["ROS_DISCOVERY_SERVER"] == ";192.168.1.10:11811"  # linked to server 1, own slot empty


def test_every_robot_container_runs_under_docker_init() -> None:
    """A process as PID 1 without a SIGTERM handler of its own ignores `docker stop` and is killed after the timeout:
    components and discovery servers alike get Docker's init (run and compose). The Fast DDS server's asks it to
    signal the whole process group, so that SIGTERM reaches the server behind the ``fastdds`` tool's wrappers,
    which the script then lets ignore it; a component's init signals its child alone."""
    p = project(discovery={"servers": [{"host": "pi", "port": 12000}, {"host": "dev"}]})
    specs = host_specs(p, "dev") + host_specs(p, "pi")
    assert {s.role for s in specs} == {naming.ROLE_COMPONENT, naming.ROLE_DISCOVERY}
    for spec in specs:
        assert spec.docker_kwargs()["init"] is True and spec.compose_service()["init"] is True, spec.name
        assert (naming.INIT_SIGNALS_GROUP in spec.env) == (spec.role == naming.ROLE_DISCOVERY), spec.name
    lines = [line.strip() for line in server_script.DISCOVERY_SCRIPT_LINES]  # SIGTERM ignored only after the hold
    assert lines.index('trap "" TERM;') > max(i for i, line in enumerate(lines) if "sleep" in line and "$left" in line)
    assert f'if [ -z "${{{naming.INIT_SIGNALS_GROUP}:-}}" ]; then rm -f "$state/alive"; exec "$@"; fi;' in lines
    assert "\n" not in dds.DISCOVERY_SCRIPT  # one line in compose files and pods


def test_tag_uses_the_registry() -> None:
    p = project(registry="registry.local:5000")
    assert component_spec(p, p.robot.component("talker"), tag="v1.2").image == "registry.local:5000/myrobot-talker:v1.2"


# ------------------------------------------------------------------ hash and labels


def test_spec_hash_is_stable_and_sensitive() -> None:
    assert talker().spec_hash == talker().spec_hash
    assert talker(environment={"A": "1"}).spec_hash != talker().spec_hash
    assert talker(launch_args="--other").spec_hash != talker().spec_hash
    labels = talker().labels
    assert labels[naming.LABEL_SPEC] == talker().spec_hash
    assert labels[naming.LABEL_PROJECT] == "myrobot"
    assert labels[naming.LABEL_COMPONENT] == "talker"
    assert labels[naming.LABEL_ROLE] == "component"


def test_changing_one_component_changes_only_its_hash() -> None:
    before = {s.name: s.spec_hash for s in host_specs(project(), "dev") + host_specs(project(), "pi")}
    changed = project(components=components_with(environment={"NEW": "x"}))
    after = {s.name: s.spec_hash for s in host_specs(changed, "dev") + host_specs(changed, "pi")}
    assert {n for n in before if before[n] != after[n]} == {"myrobot-talker"}


def test_docker_kwargs_and_compose_agree() -> None:
    spec = talker()
    kwargs, service = spec.docker_kwargs(), spec.compose_service()
    assert kwargs["image"] == service["image"]
    assert kwargs["name"] == service["container_name"]
    assert kwargs["environment"] == service["environment"]  # no "$" in these values
    assert kwargs["labels"] == service["labels"]
    assert kwargs["entrypoint"] == service["entrypoint"]
    assert kwargs["command"] == service["command"]
    assert kwargs["network_mode"] == service["network_mode"]
    assert kwargs["ipc_mode"] == service["ipc"]
    assert [f"{m['Source']}:{m['Target']}" + (":ro" if m["ReadOnly"] else "") for m in kwargs["mounts"]] \
        == service["volumes"]


# ------------------------------------------------------------------ run's decisions


def existing(spec: ContainerSpec, **changes: Any) -> Existing:
    state = Existing(name=spec.name, spec_hash=spec.spec_hash, image_id="sha256:a", running=True, role=spec.role)
    return replace(state, **changes)


def test_decide() -> None:
    p = project(discovery={"servers": [{"host": "dev"}]})
    disc, talk = host_specs(p, "dev")
    images = {disc.image: "sha256:a", talk.image: "sha256:a"}
    assert decide([disc, talk], [], images) == [Action("create", disc.name), Action("create", talk.name)]
    same = [existing(disc), existing(talk)]
    assert [a.verb for a in decide([disc, talk], same, images)] == ["keep", "keep"]
    assert decide([disc, talk], [existing(disc), existing(talk, spec_hash="old")], images)[1] == \
        Action("replace", talk.name, "configuration changed")
    assert decide([disc, talk], [existing(disc), existing(talk, image_id="sha256:b")], images)[1] == \
        Action("replace", talk.name, "new image")
    assert decide([disc, talk], [existing(disc, running=False), existing(talk)], images)[0].verb == "start"
    gone = Existing(name="myrobot-old", spec_hash="x", image_id="y", running=True, role="component")
    actions = decide([disc, talk], [*same, gone], images)
    assert actions[0] == Action("remove", "myrobot-old", "no longer planned on this host")
    assert [a.verb for a in actions[1:]] == ["keep", "keep"]


def test_compose_escapes_dollars_run_does_not() -> None:
    spec = talker(environment={"GREETING": "cost $5"}, entrypoint="sh -c 'echo $HOME'")
    assert spec.env["GREETING"] == "cost $5"
    assert spec.docker_kwargs()["environment"]["GREETING"] == "cost $5"
    assert spec.docker_kwargs()["command"] == ["sh", "-c", "echo $HOME", "--ros-args", "-p", "rate:=2"]
    service = spec.compose_service()
    assert service["environment"]["GREETING"] == "cost $$5"
    assert service["command"][2] == "echo $$HOME"


def test_uptime_text() -> None:
    from datetime import datetime, timezone

    from robocore.commands.support.status_table import uptime_text

    now = datetime(2026, 1, 2, 3, 4, 5, tzinfo=timezone.utc)
    assert uptime_text("2026-01-02T03:04:00.123456789Z", now) == "5s"  # whole seconds
    assert uptime_text("2026-01-02T02:54:05Z", now) == "10m 0s"
    assert uptime_text("2026-01-01T01:00:00.5Z", now) == "1d 2h"
    assert uptime_text("0001-01-01T00:00:00Z", now) == "-"  # never started
    assert uptime_text("", now) == "-"
