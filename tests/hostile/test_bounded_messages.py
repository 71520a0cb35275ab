"""Every value echoed in an error or warning is cut (``ui.MAX_ECHO`` characters, with its length), for
every option of every task and every robot.yaml field; messages name the real cause in the user's words.

Each case runs the command in process as a user would (``cli.main``), with a 120,000-character value, and reads
what reached the terminal; ``DOCKER_HOST`` points at a socket nobody serves, and every task that has one runs
with ``--dry-run``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
import yaml
from in_process import run_main

from robocore import ui
from robocore.config.model import Component, Host, Robot
from robocore.tasks import namespace

BIG = "x" * 120_000
WORDS = "ab " * 40_000
GOOD = ("ros_distro: jazzy\nhosts:\n  - {name: dev, ip: 192.168.1.10}\n"
        "components:\n  - {name: talker, runs_on: dev, image: 'vendor/talker:1'}\n")
#: No line that reaches the terminal is longer (the cut value says its length after it).
LONGEST = ui.MAX_LINE + 40


@pytest.fixture
def project(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    root = tmp_path / "robot"
    root.mkdir()
    (root / "robot.yaml").write_text(GOOD)
    monkeypatch.setenv("DOCKER_HOST", f"unix://{tmp_path}/nobody.sock")
    monkeypatch.setenv("ROBOCORE_NO_MEMO", "1")
    monkeypatch.chdir(root)
    return root


def check_bounded(err: str) -> None:
    assert "Traceback" not in err
    assert all(len(line) <= LONGEST for line in err.splitlines()), max(len(line) for line in err.splitlines())
    assert len(err) < 8 * LONGEST, len(err)


def option_lines() -> list[list[str]]:
    lines = []
    for name in sorted(namespace.task_names):
        arguments = namespace[name].get_arguments()
        dry = ["--dry-run"] if any("dry-run" in a.names for a in arguments) else []
        for argument in arguments:
            if argument.kind in (str, list):
                flag = f"--{argument.names[0]}"
                for value in (BIG, WORDS):
                    given = ["--component", "talker"] if name in ("shell", "connect") and flag != "--component" else []
                    lines.append([name, *given, flag, value, *dry])
    lines += [["init", BIG, "--dry-run"], ["init", "x", "--distro", BIG, "--dry-run"],
              ["init", "x", "--base", WORDS, "--dry-run"], [BIG], ["-p", BIG, "validate"], [BIG, "validate"],
              ["validate", f"--{BIG}"], ["-D", "9" * 5000, "validate"]]
    return lines


@pytest.mark.parametrize("argv", option_lines(), ids=lambda a: " ".join(x if len(x) < 20 else f"<{len(x)}>" for x in a))
def test_every_option_value_is_cut_in_what_comes_back(argv: list[str], project: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_main(argv, capsys)
    check_bounded(err)
    if code:
        assert err.strip(), "refused without a word"
    assert "set_int_max_str_digits" not in err and "int() with base" not in err


def test_a_long_value_says_its_length(project: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The reproduction: ``logs --component <120,000 characters> --dry-run`` printed a 120 KB error."""
    code, _, err = run_main(["logs", "--component", BIG, "--dry-run"], capsys)
    assert code == 2
    (line,) = err.splitlines()
    assert "unknown component 'xxxx" in line and "(120,000 characters)" in line and len(line) < 400


def test_json_problems_are_cut_too(project: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run_main(["logs", "--component", BIG, "--dry-run", "--json"], capsys)
    assert code == 2
    (problem,) = json.loads(out)["problems"]
    assert "(120,000 characters)" in problem["message"] and len(problem["message"]) < 400


def field_documents() -> list[tuple[str, str]]:
    """robot.yaml with one field (or key) of each model set to a huge value."""
    base = yaml.safe_load(GOOD)
    docs = []
    for value_id, value in (("word", BIG), ("words", WORDS)):
        for field in Robot.model_fields:
            docs.append((f"{field}-{value_id}", {**base, field: value}))
        for field in Host.model_fields:
            docs.append((f"hosts.{field}-{value_id}", {**base, "hosts": [{**base["hosts"][0], field: value}]}))
        for field in Component.model_fields:
            docs.append((f"components.{field}-{value_id}",
                         {**base, "components": [{**base["components"][0], field: value}]}))
        for field in ("apt_packages", "pip_packages", "devices", "ports", "volumes"):
            docs.append((f"components.{field}[0]-{value_id}",
                         {**base, "components": [{**base["components"][0], field: [value]}]}))
        docs.append((f"key-{value_id}", {**base, value: 1}))
        docs.append((f"hosts.key-{value_id}", {**base, "hosts": [{**base["hosts"][0], value: 1}]}))
        docs.append((f"environment-{value_id}",
                     {**base, "components": [{**base["components"][0], "environment": {value: value}}]}))
        docs.append((f"tls-{value_id}", {**base, "hosts": [{**base["hosts"][0], "docker": "tls", "tls": {
            "ca_cert": value, "client_cert": value, "client_key": value}}]}))
    return [(case, yaml.safe_dump(doc, width=1 << 30)) for case, doc in docs]


@pytest.mark.parametrize(("case", "text"), field_documents(), ids=[case for case, _ in field_documents()])
def test_every_robot_yaml_field_is_cut_in_what_comes_back(case: str, text: str, project: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    (project / "robot.yaml").write_text(text)
    _, _, err = run_main(["validate"], capsys)
    check_bounded(err)


# ------------------------------------------------------------------------------ exact words


def tls_project(root: Path, path: str) -> None:
    (root / "robot.yaml").write_text(
        "ros_distro: jazzy\nhosts:\n  - name: dev\n    ip: 192.168.1.10\n    docker: tls\n"
        f"    tls: {{ca_cert: '{path}', client_cert: certs/cert.pem, client_key: certs/key.pem}}\n")
    (root / "certs").mkdir(exist_ok=True)
    for name in ("cert.pem", "key.pem"):
        (root / "certs" / name).write_text("x")


def test_a_dotdot_tls_path_is_not_called_a_symlink(project: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (project.parent / "ca.pem").write_text("x")
    tls_project(project, "../ca.pem")
    code, _, err = run_main(["validate"], capsys)
    assert code == 2
    (line,) = [line for line in err.splitlines() if "ca_cert" in line]
    assert "names a file outside the project folder" in line and "symlink" not in line


def test_a_linked_tls_path_is_called_a_symlink(project: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (project.parent / "ca.pem").write_text("x")
    (project / "ca.pem").symlink_to(project.parent / "ca.pem")
    tls_project(project, "ca.pem")
    code, _, err = run_main(["validate"], capsys)
    assert code == 2
    (line,) = [line for line in err.splitlines() if "ca_cert" in line]
    assert "leads through a symlink to a file outside the project folder" in line


def test_a_huge_number_in_a_flag_is_in_the_users_words(project: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_main(["-T", "9" * 5000, "validate"], capsys)
    assert code == 2
    assert "a number of 5000 digits is too large" in err and "sys." not in err
    code, _, err = run_main(["-D", "abc", "validate"], capsys)
    assert code == 2 and "not a whole number: 'abc'" in err and "int()" not in err


def test_a_linked_tls_file_is_not_read_nor_echoed_whole(project: Path, capsys: pytest.CaptureFixture[str]) -> None:
    os.mkfifo(project / "ca.pem")
    tls_project(project, "ca.pem")
    code, _, err = run_main(["validate"], capsys)
    assert code == 2 and "not a regular file" in err
