"""Hostile command lines: each one is refused with one line and exit code 2, or accepted; never a traceback.

Most run in-process through ``robocore.cli.main([...])`` (fast); a handful through ``python -m robocore``
(the real entry point, which also warms ssh connections before parsing). Lines that try to run a
command (``$(touch MARKER)``, ``;touch MARKER``) must leave no marker behind, and no line may print
a raw terminal control character.
"""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from in_process import run_main

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

#: Replaced by a path in the test's tmp folder: a command that ran would leave this file.
MARK = "@MARK@"
ESC = "\x1b"
TITLE = "\x1b]0;pwned\x07"


@dataclass(frozen=True)
class Case:
    """A command line (after ``robocore``) and what must come of it."""

    argv: tuple[str, ...]
    code: int  # 0: accepted; 2: refused with one line
    says: str = ""  # a piece of the error line (refused) or of stdout (accepted)

    @property
    def id(self) -> str:
        return " ".join(self.argv).encode("unicode_escape").decode()[:60] or "(empty)"


def refused(*argv: str, says: str = "") -> Case:
    return Case(tuple(argv), 2, says)


def accepted(*argv: str, says: str = "") -> Case:
    return Case(tuple(argv), 0, says)


CASES = [
    # numeric flags
    refused("logs", "--tail", "abc", says="--tail takes a whole number"),
    refused("logs", "--tail", "-5", says="--tail takes a whole number"),
    refused("logs", "--tail=-5", says="--tail takes a whole number"),
    refused("logs", "--tail", "1e3", says="got '1e3'"),
    refused("logs", "--follow", "--tail", f"$(touch {MARK})", says="--tail takes a whole number"),
    refused("-D", "abc", "validate", says="a flag's value is not valid"),
    refused("-T", "-1x", "validate", says="a flag's value is not valid"),
    refused("--list", "--list-format", "bogus", says="--list-format 'bogus': choose one of"),
    # image tags
    refused("run", "--tag", "a;b", says="not a valid image tag"),
    refused("run", "--tag", f"$(touch {MARK})", says="not a valid image tag"),
    refused("run", "--tag", "v1\n", says="not a valid image tag"),
    refused("run", "--tag", "-x", says="not a valid image tag"),
    refused("run", "--tag", "x" * 129, says="not a valid image tag"),
    refused("release", "--tag", "../x", says="not a valid image tag"),
    # the project folder
    refused("-p", "", "validate", says="-p needs a project folder"),
    refused("-p", says="-p needs a project folder"),
    refused("--project=", "validate", says="--project= needs a project folder"),
    refused("--project=/nonexistent", "validate", says="project folder does not exist"),
    # names that are not in robot.yaml
    refused("shell", "--component", f"$(touch {MARK})", says="unknown component"),
    refused("shell", "--component", "a\nb", says="unknown component 'a\\nb'"),
    refused("shell", says="shell needs --component"),
    refused("connect", "--component", TITLE, says="unknown component '\\x1b]0;pwned\\x07'"),
    # empty values: refused in one line, never read as "not given" (down --host "" once removed every host's)
    refused("connect", "--component", "", says="--component was given an empty value"),
    refused("export", "kubernetes", "", "--tag", "v1", "--dry-run", says="DIR was given an empty value"),
    refused("export", "kubernetes", " ", "--tag", "v1", says="DIR was given an empty value"),
    refused("export", "kubernetes", "out", "--model", "", "--tag", "v1", says="--model was given an empty value"),
    refused("down", "--host", "", "--dry-run", says="--host was given an empty value"),
    refused("down", "--host=", says="--host was given an empty value"),
    refused("run", "--host", " ", "--dry-run", says="--host was given an empty value"),
    refused("sync", "--host", "", "--dry-run", says="--host was given an empty value"),
    refused("rollback", "--host", "", "--dry-run", says="--host was given an empty value"),
    refused("doctor", "--host", "", says="--host was given an empty value"),
    refused("logs", "--component", "", "--dry-run", says="--component was given an empty value"),
    refused("build", "--component", "", "--dry-run", says="--component was given an empty value"),
    refused("stage", "-c", "", "--dry-run", says="--component was given an empty value"),
    refused("test", "--component", "", "--dry-run", says="--component was given an empty value"),
    refused("test", "--packages-select", "", "--dry-run", says="--packages-select was given an empty value"),
    refused("dev", "--component", "", "--dry-run", says="--component was given an empty value"),
    refused("shell", "--component", "talker", "--cmd", "", "--dry-run", says="--cmd was given an empty value"),
    refused("shell", "--component", "talker", "--devices", "", "--dry-run", says="--devices was given an empty"),
    refused("run", "--tag", "", "--dry-run", says="--tag was given an empty value"),
    refused("release", "--tag", "", "--dry-run", says="--tag was given an empty value"),
    refused("init", "", "--dry-run", says="PATH was given an empty value"),
    refused("init", "x", "--distro", "", "--dry-run", says="--distro was given an empty value"),
    refused("connect", "--component", says="needed value"),
    refused("stage", "--component", "../x", says="unknown component"),
    refused("build", "--component", "x\ny", says="unknown component"),
    refused("logs", "--component", f";touch {MARK}", says="unknown component"),
    refused("sync", "--host", "-oProxyCommand=touch " + MARK, says="unknown host"),
    refused("sync", "--host=-oProxyCommand=x", says="unknown host '-oProxyCommand=x'"),
    refused("run", "--host", f"; touch {MARK}", says="unknown host"),
    refused("down", "--host", f"$(touch {MARK})", says="unknown host"),
    refused("rollback", "--host", "`id`", says="unknown host"),
    # the command line itself
    refused("nosuchtask", says="No idea what 'nosuchtask' is"),
    refused("", says="No idea what '' is"),
    refused(TITLE, says="No idea what '\\x1b]0;pwned\\x07' is"),
    refused("validate", "--bogus", says="No idea what '--bogus' is"),
    refused("schema", "--bogus", says="No idea what '--bogus' is"),
    refused("--bogus", says="No idea what '--bogus' is"),
    refused("init", "--", "-x", says="did not receive required positional arguments"),
    refused("validate", "--", "rm", "-rf", "/", says="no arguments after '--'"),
    refused("init", "--distro", "iron", "newrobot", says="--distro 'iron': unknown"),
    refused("shell", "--component", "talker", "--devices", "sda", "--dry-run", says="--devices takes only 'all'"),
    # accepted: well-formed lines, dry runs that contact nobody
    accepted("validate", says=""),
    accepted("logs", "--tail", "0", "--dry-run", says="would read logs"),
    accepted("run", "--dry-run", "--tag", "v1.2_rc-3", says="talker"),
    accepted("run", "-d", "--host", "dev", says="listener"),
    accepted("down", "--dry-run", says="which ones: unknown (dry run: not contacted)"),
    accepted("status", "--dry-run", says="would list"),
    accepted("validate", "--", says=""),
]


def test_there_are_enough_hostile_lines() -> None:
    assert sum(1 for case in CASES if case.code == 2) >= 30


@pytest.fixture
def project(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    root = tmp_path / "robot"
    for folder in ("components/talker/src", "components/listener/src"):
        (root / folder).mkdir(parents=True)
    (root / "robot.yaml").write_text(ROBOT_YAML)
    monkeypatch.setenv("DOCKER_HOST", f"unix://{tmp_path}/no-daemon.sock")  # nothing listens there
    monkeypatch.chdir(root)
    return root


def check(case: Case, code: int, out: str, err: str, marker: Path) -> None:
    assert "Traceback" not in out + err, err
    assert code == case.code, (code, out, err)
    assert ESC not in out + err and "\x07" not in out + err, "a raw control character reached the terminal"
    if case.code == 2:
        lines = [line for line in err.splitlines() if line.strip()]
        problems = [line for line in lines if not line.startswith("hint:")]
        assert len(problems) == 1 and len(lines) <= 2, lines
        assert case.says in problems[0], (case.says, problems[0])
    else:
        assert case.says in out + err, (case.says, out, err)
    assert not marker.exists(), f"{case.argv} ran a command"


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_hostile_line_in_process(case: Case, project: Path, capsys: pytest.CaptureFixture[str]) -> None:
    marker = project.parent / "MARKER"
    argv = [arg.replace(MARK, str(marker)) for arg in case.argv]
    code, out, err = run_main(argv, capsys)
    check(case, code, out, err, marker)


def test_nothing_was_written_by_refused_lines(project: Path, capsys: pytest.CaptureFixture[str]) -> None:
    before = sorted(p.relative_to(project.parent) for p in project.parent.rglob("*"))
    for case in CASES:
        if case.code == 2 and "init" not in case.argv:
            run_main([arg.replace(MARK, str(project.parent / "MARKER")) for arg in case.argv], capsys)
    assert sorted(p.relative_to(project.parent) for p in project.parent.rglob("*")) == before


SUBPROCESS_CASES = [
    refused("logs", "--tail", "abc", says="--tail takes a whole number"),
    refused("run", "--tag", f"$(touch {MARK})", says="not a valid image tag"),
    refused(TITLE, says="No idea what"),
    refused("-p", "", "validate", says="-p needs a project folder"),
    refused("sync", "--host", f"-oProxyCommand=touch {MARK}", says="unknown host"),
    accepted("sync", "-d", "--host", "dev", says="this machine, nothing to copy"),
]


@pytest.mark.parametrize("case", SUBPROCESS_CASES, ids=lambda c: c.id)
def test_hostile_line_through_the_console_script(case: Case, project: Path) -> None:
    marker = project.parent / "MARKER"
    env = dict(os.environ)
    done = subprocess.run([sys.executable, "-m", "robocore", *(a.replace(MARK, str(marker)) for a in case.argv)],
                          capture_output=True, text=True, cwd=project, env=env, timeout=60)
    check(case, done.returncode, done.stdout, done.stderr, marker)


def test_invoke_in_a_project_checks_numeric_flags_too(project: Path) -> None:
    """The project's own ``invoke`` (not the robocore command) runs the same tasks: one line, no traceback."""
    (project / "tasks.py").write_text("from robocore.tasks import namespace  # noqa: F401\n")
    invoke = Path(sys.executable).with_name("invoke")
    env = dict(os.environ)
    done = subprocess.run([str(invoke), "logs", "--tail", "abc"], capture_output=True, text=True, cwd=project,
                          env=env, timeout=60)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert done.stderr.strip() == "error: --tail takes a whole number from 0 to 10,000,000 (got 'abc')"


@pytest.mark.parametrize("value", [TITLE, "10.0.0.1\x1b[2J", "\u202etxt.exe"])
def test_control_characters_from_robot_yaml_never_reach_the_terminal(
        value: str, project: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """An address with a terminal sequence: refused or printed escaped (whatever robot.yaml's checks say)."""
    import json

    (project / "robot.yaml").write_text(ROBOT_YAML.replace('"10.99.0.1"', json.dumps(value)))
    for argv in (["validate"], ["run", "--dry-run"], ["sync", "--dry-run"], ["down", "-d"]):
        code, out, err = run_main(argv, capsys)
        assert "Traceback" not in out + err
        assert ESC not in out + err and "\x07" not in out + err and "\u202e" not in out + err, (argv, out, err)
        assert code in (0, 2), (argv, code, err)
