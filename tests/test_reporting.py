"""The Reporter: one JSON document per task, problems from every kind of error, JSON Lines for streams."""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import ClassVar

import pytest
from fakes import FakeContainer

from robocore.commands import logs
from robocore.commands.support.reporting import Reporter, error_problems
from robocore.errors import ConfigError, DockerError, GroupError, HostError, Problem, UsageError


@dataclass(frozen=True)
class Thing:
    kind: ClassVar[str] = "thing"
    name: str
    size: int


def test_finish_prints_one_envelope_once(capsys: pytest.CaptureFixture[str]) -> None:
    report = Reporter("demo", json=True)
    report.add(Thing("a", 1), Thing("b", 2))
    report.plain("a plan for people")
    report.out("a line for people")
    report.finish()
    report.finish()  # printed once, whatever happens after
    report.fail(UsageError("too late"))
    doc = json.loads(capsys.readouterr().out)
    assert doc == {"schema_version": 1, "task": "demo", "ok": True,
                   "results": [{"kind": "thing", "name": "a", "size": 1}, {"kind": "thing", "name": "b", "size": 2}],
                   "problems": []}


def test_without_json_nothing_is_printed_for_programs(capsys: pytest.CaptureFixture[str]) -> None:
    report = Reporter("demo")
    report.add(Thing("a", 1))
    report.plain("a plan for people")
    report.finish()
    assert capsys.readouterr().out == "a plan for people\n"


def test_a_warning_is_a_problem_but_the_task_is_ok(capsys: pytest.CaptureFixture[str]) -> None:
    report = Reporter("validate", json=True)
    report.warn("privileged", Problem("robot.yaml", 9, "components[0].privileged", "privileged", "warning"))
    report.finish()
    doc = json.loads(capsys.readouterr().out)
    assert doc["ok"] is True
    assert doc["problems"] == [{"file": "robot.yaml", "line": 9, "key": "components[0].privileged",
                                "message": "privileged", "severity": "warning", "hint": None}]


def test_problems_of_each_kind_of_error() -> None:
    config = ConfigError([Problem("robot.yaml", 3, "hosts[0].ip", "not an address"),
                          Problem("robot.yaml", None, "", "empty")])
    assert [(p["file"], p["line"], p["key"], p["message"]) for p in error_problems(config)] == [
        ("robot.yaml", 3, "hosts[0].ip", "not an address"), ("robot.yaml", None, None, "empty")]
    docker = DockerError("no daemon", hint="start it")
    assert error_problems(docker) == [{"file": None, "line": None, "key": None, "message": "no daemon",
                                       "severity": "error", "hint": "start it"}]
    group = GroupError({"b": HostError("host b: down", hint="power it"), "a": HostError("host a: gone")}, ["c"])
    assert [(p["message"], p["hint"]) for p in error_problems(group)] == [
        ("a: host a: gone", None), ("b: host b: down", "power it")]


def test_fail_prints_the_results_so_far_and_the_problems(capsys: pytest.CaptureFixture[str]) -> None:
    report = Reporter("run", json=True)
    report.add(Thing("kept", 0))
    report.fail(GroupError({"main": HostError("host main: unreachable")}, []))
    doc = json.loads(capsys.readouterr().out)
    assert doc["ok"] is False and doc["results"] == [{"kind": "thing", "name": "kept", "size": 0}]
    assert [p["message"] for p in doc["problems"]] == ["main: host main: unreachable"]


def test_logs_follow_json_is_json_lines_then_the_envelope(capsys: pytest.CaptureFixture[str]) -> None:
    report = Reporter("logs", json=True)
    logs.follow_logs(report, [("main", "talker", FakeContainer([b"hello\n", b"again\n"]))], 6, 10)
    report.finish()
    lines = capsys.readouterr().out.splitlines()
    docs = [json.loads(line) for line in lines]  # every line is one object
    assert docs[:2] == [{"kind": "log", "component": "talker", "host": "main", "line": "hello"},
                        {"kind": "log", "component": "talker", "host": "main", "line": "again"}]
    assert docs[2]["task"] == "logs" and docs[2]["ok"] is True and len(docs) == 3


def test_logs_follow_without_json_prints_prefixed_lines(capsys: pytest.CaptureFixture[str]) -> None:
    """Negative control: the same stream for people is text, not JSON."""
    report = Reporter("logs")
    logs.follow_logs(report, [("main", "talker", FakeContainer([b"hello\n"]))], 6, 10)
    report.finish()
    assert capsys.readouterr().out == "talker | hello\n"
