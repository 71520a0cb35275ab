"""fleet.yaml: the model, its file:line:key problems, its checks against robot.yaml, and its JSON Schema."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import jsonschema
import pytest
import yaml

from robocore.config import fleet_checks
from robocore.config.fleet import FLEET_FILE, REST_WAVE, Fleet, load_fleet, parse_fleet_text
from robocore.config.loader import parse_robot_text
from robocore.config.model import Robot
from robocore.config.schema import FLEET_SCHEMA_ID, fleet_schema
from robocore.errors import ConfigError

ROBOT = """\
ros_distro: jazzy
registry: 10.0.0.2:5000
hosts:
  - {name: main, ip: 192.168.1.10, user: me}
  - {name: arm, ip: 192.168.1.20, arch: arm64, docker: ssh}
components:
  - {name: talker, folder: components/talker, runs_on: main}
  - {name: listener, folder: components/listener, runs_on: arm}
"""

FLEET = """\
engine: swarm
manager:
  ip: 10.0.0.2
  user: root
robots:
  - name: r1
    labels: {site: lab}
    hosts:
      main: {ip: 10.0.1.5, user: root}
      arm: {ip: 10.0.1.6}
    ros_domain_id: 3
  - name: r2
    hosts:
      main: {ip: 10.0.2.5}
      arm: {ip: 10.0.2.6, ssh_port: 2222}
rollout:
  waves:
    - {name: canary, robots: [r1]}
    - {name: rest}
  health: {running: 5, nodes: [/talker, /listener], heard: [/chatter]}
  timeouts: {robot: 60, wave: 300}
"""


@pytest.fixture(scope="module")
def robot() -> Robot:
    return parse_robot_text(ROBOT)


def refusal(text: str, robot: Robot) -> list[str]:
    with pytest.raises(ConfigError) as caught:
        parse_fleet_text(text, robot)
    return caught.value.lines()


def test_a_fleet_file_loads_into_frozen_models(robot: Robot) -> None:
    fleet = parse_fleet_text(FLEET, robot)
    assert fleet.engine == "swarm" and fleet.manager is not None and fleet.manager.ip == "10.0.0.2"
    assert fleet.robot_names == ["r1", "r2"]
    assert fleet.robot("r1").hosts["main"].user == "root" and fleet.robot("r1").ros_domain_id == 3
    assert fleet.robot("r2").hosts["arm"].ssh_port == 2222
    assert fleet.rollout.health.nodes == ["/talker", "/listener"] and fleet.rollout.timeouts.wave == 300
    assert fleet.registry_for(robot) == "10.0.0.2:5000"
    with pytest.raises(ValueError):
        fleet.robots[0].name = "x"  # type: ignore[misc]
    host = fleet.manager.as_host()
    assert (host.name, host.ip, host.user, host.access.value) == ("manager", "10.0.0.2", "root", "ssh")


def test_the_defaults_of_a_minimal_file(robot: Robot) -> None:
    fleet = parse_fleet_text("manager: {ip: mgr.lan}\nrobots:\n  - {name: a, hosts: {main: {ip: a1.lan}, arm: "
                             "{ip: a2.lan}}}\n", robot)
    assert fleet.engine == "swarm" and fleet.registry is None and fleet.rollout.waves == []
    assert (fleet.rollout.health.running, fleet.rollout.timeouts.robot) == (10, 120)


def test_field_errors_name_the_fleet_file_line_and_key(robot: Robot) -> None:
    text = FLEET.replace("ros_domain_id: 3", "ros_domain_id: 300").replace("engine: swarm", "engine: nomad")
    text = text.replace("heard: [/chatter]", "heard: [chatter]")
    text += "colour: blue\n"
    assert refusal(text, robot) == [
        "fleet.yaml:1: engine: 'nomad' is not one of: swarm, kubernetes",
        "fleet.yaml:11: robots[0].ros_domain_id: 300 is out of range (must be at most 232)",
        "fleet.yaml:20: rollout.health.heard[0]: 'chatter' is not a valid value here (expected an absolute ROS name "
        "such as /talker or /robot/chatter)",
        "fleet.yaml:22: colour: unknown key 'colour'; did you mean 'rollout'? (allowed: engine, gitops, manager, "
        "registry, registry_ca, robots, rollout)",
    ]


def test_every_host_of_robot_yaml_is_given_by_every_robot_and_no_other(robot: Robot) -> None:
    text = FLEET.replace("      arm: {ip: 10.0.1.6}\n", "      armm: {ip: 10.0.1.6}\n")
    assert refusal(text, robot) == [
        "fleet.yaml:8: robots[0].hosts: robot 'r1' gives no address for host(s) arm of robot.yaml; every robot "
        "gives one for each host",
        "fleet.yaml:10: robots[0].hosts.armm: unknown host 'armm' (known: main, arm); did you mean 'arm'?",
    ]


def test_duplicate_names_and_addresses_and_loopback_are_refused(robot: Robot) -> None:
    text = FLEET.replace("name: r2", "name: r1").replace("10.0.2.6", "10.0.1.5").replace("10.0.2.5", "127.0.0.1")
    assert refusal(text, robot) == [
        "fleet.yaml:12: robots[1].name: duplicate robot name 'r1' (also robots[0])",
        "fleet.yaml:14: robots[1].hosts.main.ip: '127.0.0.1' is a loopback address; a fleet's hosts are reached "
        "from the manager and from each other, so each needs its network address",
        "fleet.yaml:15: robots[1].hosts.arm.ip: address '10.0.1.5' is also robots[0].hosts.main (robot 'r1'); "
        "each host of each robot is one machine",
    ]


def test_addresses_compare_as_addresses(robot: Robot) -> None:
    text = FLEET.replace("10.0.1.5", "fd00::1").replace("10.0.2.5", "FD00:0::1").replace("10.0.1.6", "Bot.lan")
    text = text.replace("10.0.2.6", "bot.lan")
    lines = refusal(text, robot)
    assert [line.split(": ")[1] for line in lines] == ["robots[1].hosts.main.ip", "robots[1].hosts.arm.ip"]


def test_wave_selectors_are_checked(robot: Robot) -> None:
    text = FLEET.replace("""    - {name: canary, robots: [r1]}
    - {name: rest}
""", """    - {name: canary, robots: [r1, r9]}
    - {name: canary, robots: [r1], percent: 10}
    - {name: again, robots: [r1]}
    - {name: rest, percent: 50}
    - {name: all}
    - {name: late, labels: {site: lab}}
""")
    assert refusal(text, robot) == [
        "fleet.yaml:18: rollout.waves[0].robots[1]: unknown robot 'r9' (known: r1, r2)",
        "fleet.yaml:19: rollout.waves[1]: a wave takes one selector, not robots and percent",
        "fleet.yaml:20: rollout.waves[2].robots[0]: robot 'r1' is already named by wave 'canary' (rollout.waves[0])",
        "fleet.yaml:21: rollout.waves[3].name: 'rest' is the wave of every robot not yet placed and takes no "
        "selector; give this wave another name",
        "fleet.yaml:23: rollout.waves[5].name: wave 'late' comes after wave 'all', which takes every robot left (it "
        "has no selector); it would always be empty",
    ]


def test_the_swarm_engine_needs_a_manager_and_a_fleet_a_registry() -> None:
    bare = parse_robot_text(ROBOT.replace("registry: 10.0.0.2:5000\n", ""))
    text = FLEET.replace("manager:\n  ip: 10.0.0.2\n  user: root\n", "")
    assert refusal(text, bare) == [
        "fleet.yaml:1: manager: the swarm engine needs its manager (manager: {ip: ..., user: ...})",
        "fleet.yaml:1: registry: a fleet runs release images from a registry: set registry here or in robot.yaml "
        "(e.g. registry: 10.0.0.2:5000)",
    ]
    fleet = parse_fleet_text("engine: kubernetes\nregistry: reg.lan:5000\n" + text.split("\n", 1)[1], bare)
    assert fleet.manager is None and fleet.registry_for(bare) == "reg.lan:5000"


def test_a_field_error_and_a_cross_check_are_reported_in_one_run(robot: Robot) -> None:
    text = FLEET.replace("ros_domain_id: 3", "ros_domain_id: x").replace("name: r2", "name: r1")
    lines = refusal(text, robot)
    assert any("robots[0].ros_domain_id: expected a whole number" in line for line in lines)
    assert any("duplicate robot name 'r1'" in line for line in lines)


def test_the_top_level_must_be_a_mapping_and_yaml_errors_are_one_line(robot: Robot) -> None:
    assert refusal("- a\n- b\n", robot) == [
        "fleet.yaml:1: top level must be a mapping of keys (engine, gitops, manager, registry, registry_ca, robots, "
        "rollout), got a list"]
    assert refusal("robots: [\n", robot)[0].startswith("fleet.yaml:2: YAML syntax error")
    assert "fleet.yaml:2: robots: this key appears twice" in refusal("robots: []\nrobots: []\n", robot)


def test_the_rest_wave_name_is_one_constant() -> None:
    assert fleet_checks.REST == REST_WAVE == "rest"


def test_load_fleet_reads_the_project_file(tmp_path: Path, robot: Robot) -> None:
    (tmp_path / FLEET_FILE).write_text(FLEET)
    assert load_fleet(tmp_path, robot).robot_names == ["r1", "r2"]
    (tmp_path / FLEET_FILE).write_text("# nothing yet\n")
    with pytest.raises(ConfigError) as caught:
        load_fleet(tmp_path, robot)
    assert caught.value.lines()[0].endswith("fleet.yaml: file is empty; see 'robocore schema --fleet' for its keys")


# ---------------------------------------------------------------- the JSON Schema


def test_robocore_schema_fleet_prints_the_fleet_schema() -> None:
    done = subprocess.run([sys.executable, "-m", "robocore", "schema", "--fleet"], capture_output=True, text=True,
                          check=True)
    schema: dict[str, Any] = json.loads(done.stdout)
    jsonschema.Draft202012Validator.check_schema(schema)
    assert schema == fleet_schema() and schema["$id"] == FLEET_SCHEMA_ID
    assert schema["additionalProperties"] is False and schema["required"] == ["robots"]


@pytest.mark.parametrize("edit, valid", [
    (lambda d: d, True),
    (lambda d: d.update(engine="nomad"), False),
    (lambda d: d["robots"][0].update(name="Robot_1"), False),
    (lambda d: d["robots"][0]["hosts"].update({"-x": {"ip": "10.9.9.9"}}), False),
    (lambda d: d["robots"][0]["hosts"]["main"].update(ip="-oProxyCommand=x"), False),
    (lambda d: d["robots"][0]["labels"].update({"site": "a b"}), False),
    (lambda d: d["rollout"]["waves"][0].update(percent=0), False),
    (lambda d: d["rollout"].update(extra=1), False),
    (lambda d: d["rollout"]["waves"].append({"name": "x", "labels": {"Bad Key": "v"}}), False),
])
def test_the_schema_agrees_with_the_model(edit: Any, valid: bool, robot: Robot) -> None:
    doc = yaml.safe_load(FLEET)
    edit(doc)
    errors = list(jsonschema.Draft202012Validator(fleet_schema()).iter_errors(doc))
    assert (not errors) == valid, errors
    try:
        Fleet.model_validate(doc)
    except ValueError:
        assert not valid
    else:
        assert valid


def test_gitops_names_the_repository_and_a_bad_url_is_one_line(robot: Robot) -> None:
    fleet = parse_fleet_text(FLEET + "gitops: {repo: 'git@git.example.org:team/fleet.git', path: k8s/fleet}\n", robot)
    assert fleet.gitops is not None
    assert (fleet.gitops.repo, fleet.gitops.path) == ("git@git.example.org:team/fleet.git", "k8s/fleet")
    assert parse_fleet_text(FLEET, robot).gitops is None
    lines = refusal(FLEET + "gitops:\n  repo: https://bot:s3cret@git.example.org/fleet.git\n  path: ../up\n", robot)
    assert [line.split(": ")[0:2] for line in lines] == [["fleet.yaml:23", "gitops.repo"],
                                                         ["fleet.yaml:24", "gitops.path"]]
    assert "password" in lines[0] and "s3cret" not in lines[0] and "bot" not in lines[0]
    assert refusal(FLEET + "gitops: {repo: 'ftp://git.example.org/fleet'}\n", robot)[0].startswith(
        "fleet.yaml:22: gitops.repo: must be a git URL")


@pytest.mark.parametrize("repo", ["https://ghp_Tok3n@github.com/team/fleet.git",
                                  "http://glpat-Tok3n@git.example.org/fleet.git"])
def test_a_user_in_an_https_gitops_url_is_refused_unshown(repo: str, robot: Robot) -> None:
    """A token can be an https URL's user, and export commits the URL: refused, the user never printed. ssh's
    ``git@`` (scp-like or ssh://) is a plain login name and stays."""
    lines = refusal(FLEET + f"gitops: {{repo: '{repo}', allow_protocol: http}}\n", robot)
    assert len(lines) == 1 and lines[0].startswith("fleet.yaml:22: gitops.repo: "), lines
    assert "Tok3n" not in lines[0] and "names a user" in lines[0] and "Secret" in lines[0]
    for fine in ("ssh://git@git.example.org/team/fleet.git", "git@git.example.org:team/fleet.git",
                 "https://git.example.org/team/fleet.git"):
        fleet = parse_fleet_text(FLEET + f"gitops: {{repo: '{fine}'}}\n", robot)
        assert fleet.gitops is not None and fleet.gitops.repo == fine


def test_a_dev_host_kept_in_a_fleet_model_is_a_warning_naming_its_line(tmp_path: Path) -> None:
    """The template's robot.yaml names this machine (127.0.0.1) as its host: in a fleet model each robot would get
    a host of that name, reached as the developer's user. validate warns, on robot.yaml's line; a robot's own
    computer (not loopback) is no warning, and a user given for every robot drops that part of it."""
    from robocore.config.loader import fleet_model_warnings, parse_robot_text

    text = ("ros_distro: jazzy\nhosts:\n  - {name: main, ip: 10.0.0.5, user: robot}\n"
            "  - {name: devmachine, ip: 127.0.0.1, user: me}\n"
            "components:\n  - {name: talker, folder: components/talker, runs_on: main, "
            "entrypoint: ros2 run demo_talker talker}\n")
    path = tmp_path / "robot.yaml"
    path.write_text(text)
    robot = parse_robot_text(text)
    warned = fleet_model_warnings(path, robot, {"main": False, "devmachine": False})
    assert [(w.line, w.path, w.severity) for w in warned] == [(4, "hosts[1].ip", "warning")], warned
    assert "devmachine is this machine (127.0.0.1), a dev host" in warned[0].message
    assert "reached as robot.yaml's user me there" in warned[0].message
    users_given = fleet_model_warnings(path, robot, {"main": False, "devmachine": True})
    assert len(users_given) == 1 and "user me" not in users_given[0].message
    robot_only = parse_robot_text(text.replace("127.0.0.1", "10.0.0.6"))
    assert fleet_model_warnings(path, robot_only, {}) == []
