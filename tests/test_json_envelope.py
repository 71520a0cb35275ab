"""``--json``: every task prints exactly one JSON object with the same envelope, also when it fails.

The project has a remote host and a local one; nothing is reachable: ``ssh``, ``rsync``, ``git`` and
``docker`` on PATH are fakes that fail, and ``DOCKER_HOST`` names a socket nobody listens on. Dry runs
are offline and succeed; ``status`` and ``doctor`` cannot reach a host and still print one object,
with ok false and the hosts' problems.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import built_project

from robocore.errors import GroupError, HostError

ROBOT_YAML = """\
ros_distro: jazzy
base: {kind: wheels}
hosts:
  - {name: main, ip: "10.99.0.1", user: robot}
  - {name: dev, ip: 127.0.0.1, user: me}
components:
  - {name: talker, folder: components/talker, runs_on: main}
  - {name: listener, folder: components/listener, runs_on: dev}
"""

ENVELOPE = {"schema_version", "task", "ok", "results", "problems"}
PROBLEM = {"file", "line", "key", "message", "severity", "hint"}


@pytest.fixture
def world(tmp_path: Path) -> dict[str, object]:
    root = tmp_path / "robot"
    built_project(root, ROBOT_YAML)
    fake_bin = tmp_path / "bin"
    fake_bin.mkdir()
    for tool in ("ssh", "rsync", "git", "docker"):
        (fake_bin / tool).write_text("#!/bin/sh\necho 'ssh: connect to host 10.99.0.1: No route' >&2\nexit 255\n")
        (fake_bin / tool).chmod(0o755)
    env = dict(os.environ)
    env.update(PATH=f"{fake_bin}:{env['PATH']}", DOCKER_HOST=f"unix://{tmp_path / 'nobody.sock'}",
               ROBOCORE_SSH_CONFIG=str(tmp_path / "ssh_config"))
    (tmp_path / "ssh_config").write_text("")
    return {"root": root, "env": env}


def robocore(world: dict[str, object], *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "robocore", "-p", str(world["root"]), *args], capture_output=True,
                          text=True, env=world["env"], timeout=120)  # type: ignore[arg-type]


def envelope(done: subprocess.CompletedProcess[str], task: str) -> dict[str, object]:
    """The one JSON object on stdout (json.loads refuses anything before or after it)."""
    assert "Traceback" not in done.stderr, done.stderr
    doc = json.loads(done.stdout)
    assert isinstance(doc, dict) and set(doc) == ENVELOPE, doc
    assert doc["schema_version"] == 1 and doc["task"] == task
    assert isinstance(doc["results"], list) and isinstance(doc["problems"], list)
    for result in doc["results"]:
        assert isinstance(result, dict) and isinstance(result.get("kind"), str), result
    for problem in doc["problems"]:
        assert set(problem) == PROBLEM and problem["message"], problem
    return doc


OFFLINE = [
    (["validate"], "robot"),
    (["stage", "--dry-run"], "image"),
    (["build", "--dry-run"], "build"),
    (["sync", "--dry-run"], "sync_plan"),
    (["run", "--dry-run"], "host_run"),
]


@pytest.mark.parametrize("argv, kind", OFFLINE, ids=lambda v: " ".join(v) if isinstance(v, list) else v)
def test_dry_runs_and_validate_print_one_envelope_with_their_plan(argv: list[str], kind: str,
                                                                  world: dict[str, object]) -> None:
    done = robocore(world, *argv, "--json")
    assert done.returncode == 0, done.stderr
    doc = envelope(done, argv[0])
    assert doc["ok"] is True and doc["problems"] == []
    assert doc["results"] and {r["kind"] for r in doc["results"]} == {kind}  # type: ignore[union-attr,index]


def test_the_plan_is_in_the_results(world: dict[str, object]) -> None:
    stage = envelope(robocore(world, "stage", "--dry-run", "--json"), "stage")
    assert all("FROM " in r["plan"] for r in stage["results"])  # type: ignore[union-attr,index]
    sync = envelope(robocore(world, "sync", "--dry-run", "--json"), "sync")
    [talker] = sync["results"]  # type: ignore[misc]
    assert talker["host"] == "main" and talker["rsync"][0] == "rsync" and talker["session"][0] == "ssh"
    run = envelope(robocore(world, "run", "--dry-run", "--json"), "run")
    assert {r["host"] for r in run["results"]} == {"main", "dev"}  # type: ignore[union-attr,index]


@pytest.mark.parametrize("task, code", [("status", GroupError.exit_code), ("doctor", HostError.exit_code)])
def test_unreachable_hosts_give_one_envelope_with_ok_false(task: str, code: int, world: dict[str, object]) -> None:
    done = robocore(world, task, "--json")
    assert done.returncode == code, (done.returncode, done.stderr)
    doc = envelope(done, task)
    assert doc["ok"] is False and doc["problems"]
    messages = " ".join(str(p["message"]) for p in doc["problems"])  # type: ignore[union-attr,index]
    assert "dev" in messages and "main" in messages, messages


def test_a_config_error_is_one_envelope_with_file_line_and_key(world: dict[str, object]) -> None:
    robot_yaml = Path(str(world["root"])) / "robot.yaml"
    robot_yaml.write_text(ROBOT_YAML.replace("runs_on: dev", "runs_on: rpi6"))
    for argv in (["validate"], ["run", "--dry-run"]):
        done = robocore(world, *argv, "--json")
        assert done.returncode == 2, done.stderr
        doc = envelope(done, argv[0])
        assert doc["ok"] is False and doc["results"] == []
        [problem] = doc["problems"]  # type: ignore[misc]
        assert str(problem["file"]).endswith("robot.yaml")
        assert (problem["line"], problem["key"]) == (8, "components[1].runs_on")
        assert "unknown host 'rpi6'" in problem["message"] and problem["severity"] == "error"
        assert "robot.yaml:8: components[1].runs_on: unknown host" in done.stderr  # the line for people stays


def test_without_json_stdout_holds_no_json(world: dict[str, object]) -> None:
    """Negative control: the envelope is --json's, not printed anyway."""
    done = robocore(world, "run", "--dry-run")
    assert done.returncode == 0 and "schema_version" not in done.stdout and "listener" in done.stdout
