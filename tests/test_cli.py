"""The robocore command: project selection, exit codes, one line per problem, no tracebacks."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import write_project
from test_config_invalid import BASE, FOLDERS, edit

from robocore.cli import CommandLineError, init_in_project, split_project

TASKS = {"validate", "shell", "stage", "prepare-base", "prepare_base", "schema", "init"}


def robocore(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ)
    return subprocess.run(
        [sys.executable, "-m", "robocore", *args], capture_output=True, text=True, cwd=cwd, env=env, timeout=60
    )


@pytest.fixture
def good(tmp_path: Path) -> Path:
    return write_project(tmp_path / "good", BASE, FOLDERS)


@pytest.fixture
def bad(tmp_path: Path) -> Path:
    text = edit({1: "ros_distro: iron", 15: "    runs_on: rpi6"}, after={15: "    nvidia: maybe"})
    return write_project(tmp_path / "bad", text, FOLDERS)


# --- argument splitting ----------------------------------------------------------------------


@pytest.mark.parametrize(
    "argv, project, rest",
    [
        (["-p", "DIR", "validate"], "DIR", ["validate"]),
        (["--project", "DIR", "validate"], "DIR", ["validate"]),
        (["--project=DIR", "validate", "--dry-run"], "DIR", ["validate", "--dry-run"]),
        (["DIR", "validate"], "DIR", ["validate"]),
        (["DIR", "prepare-base", "--force"], "DIR", ["prepare-base", "--force"]),
        (["validate"], None, ["validate"]),
        (["shell", "-c", "talker", "-p"], None, ["shell", "-c", "talker", "-p"]),  # shell's -p is --privileged
        (["DIR", "shell", "-p", "-c", "x"], "DIR", ["shell", "-p", "-c", "x"]),
        (["-f", "cfg.yaml", "DIR", "validate"], "DIR", ["-f", "cfg.yaml", "validate"]),
        (["-d", "-p", "DIR", "stage", "DIR2"], "DIR", ["-d", "stage", "DIR2"]),
        (["--help"], None, ["--help"]),
        (["nonsense", "words"], None, ["nonsense", "words"]),
    ],
)
def test_split_project(argv: list[str], project: str | None, rest: list[str]) -> None:
    assert split_project(argv, TASKS) == (project, rest)


def test_a_lone_existing_folder_is_the_project(tmp_path: Path) -> None:
    assert split_project([str(tmp_path)], TASKS) == (str(tmp_path), [])
    assert split_project([str(tmp_path / "missing")], TASKS) == (None, [str(tmp_path / "missing")])


@pytest.mark.parametrize("argv", [["-p"], ["--project"], ["--project=", "validate"], ["-p", ""]])
def test_project_flag_without_a_folder(argv: list[str]) -> None:
    with pytest.raises(CommandLineError):
        split_project(argv, TASKS)


# --- the command ------------------------------------------------------------------------------


@pytest.mark.parametrize("form", ["-p", "--project=", "positional", "cwd"])
def test_every_project_form_validates(good: Path, tmp_path: Path, form: str) -> None:
    args = {
        "-p": ["-p", str(good), "validate"],
        "--project=": [f"--project={good}", "validate"],
        "positional": [str(good), "validate"],
        "cwd": ["validate"],
    }[form]
    done = robocore(*args, cwd=good if form == "cwd" else tmp_path)
    assert done.returncode == 0, done.stderr
    assert f"{good / 'robot.yaml'}: ok — ROS 2 humble, 2 host(s), 2 component(s), base official" in done.stderr
    assert "  rpi5 (192.168.1.20, arm64, docker via ssh): talker" in done.stderr
    assert "  dev (127.0.0.1, amd64, docker via local): listener" in done.stderr
    assert "  discovery (fastdds): rpi5:11811" in done.stderr


def test_the_project_folder_reaches_the_task_as_an_argument(good: Path, tmp_path: Path,
                                                            monkeypatch: pytest.MonkeyPatch,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """``-p`` sets no environment variable; a ROBOCORE_PROJECT in the environment (what a dev shell holds:
    the project's name) is not read as a folder."""
    from robocore.cli import main

    monkeypatch.delenv("ROBOCORE_PROJECT", raising=False)
    monkeypatch.chdir(tmp_path)
    main(["-p", str(good), "validate", "--json"])
    assert json.loads(capsys.readouterr().out)["results"][0]["file"] == str(good / "robot.yaml")
    assert "ROBOCORE_PROJECT" not in os.environ
    env = {**os.environ, "ROBOCORE_PROJECT": str(tmp_path / "elsewhere")}
    done = subprocess.run([sys.executable, "-m", "robocore", "validate"], capture_output=True, text=True, cwd=good,
                          env=env, timeout=60)
    assert done.returncode == 0 and f"{good / 'robot.yaml'}: ok" in done.stderr, done.stderr


def test_relative_project_folder(good: Path) -> None:
    done = robocore("-p", good.name, "validate", cwd=good.parent)
    assert done.returncode == 0, done.stderr


def test_bad_config_exits_2_with_one_line_per_problem(bad: Path) -> None:
    done = robocore("-p", str(bad), "validate", cwd=bad.parent)
    assert done.returncode == 2
    assert done.stdout == ""
    assert done.stderr.splitlines() == [
        "error: bad/robot.yaml:1: ros_distro: 'iron' is not one of: melodic, noetic, humble, jazzy, kilted, rolling",
        "error: bad/robot.yaml:15: components[0].runs_on: unknown host 'rpi6' (known: rpi5, dev); did you mean 'rpi5'?",
        "error: bad/robot.yaml:16: components[0].nvidia: expected true or false, got 'maybe'",
    ]


def test_seed_form_reports_the_same_problems(bad: Path) -> None:
    a = robocore("-p", str(bad), "validate")
    b = robocore(str(bad), "validate")
    assert a.returncode == b.returncode == 2
    assert a.stderr == b.stderr and "Traceback" not in a.stderr


@pytest.mark.parametrize("content", ["", "ros_distro: [", "- a\n- b\n", "hosts: {}\n"])
def test_unusable_files_exit_2_without_traceback(tmp_path: Path, content: str) -> None:
    project = write_project(tmp_path / "p", content)
    done = robocore("-p", str(project), "validate")
    assert done.returncode == 2
    assert "Traceback" not in done.stderr
    assert all(line.startswith(f"error: {project / 'robot.yaml'}") for line in done.stderr.splitlines()), done.stderr


def test_missing_project(tmp_path: Path) -> None:
    done = robocore("-p", str(tmp_path / "nowhere"), "validate")
    assert done.returncode == 2
    assert done.stderr.strip() == f"error: {tmp_path / 'nowhere'}: project folder does not exist"


def test_missing_robot_yaml(tmp_path: Path) -> None:
    done = robocore("validate", cwd=tmp_path)
    assert done.returncode == 2
    assert "robot.yaml: file not found" in done.stderr and "Traceback" not in done.stderr


def test_project_flag_without_value_is_a_usage_error() -> None:
    done = robocore("-p")
    assert done.returncode == 2
    assert done.stderr.startswith("robocore: -p needs a project folder")


def test_help_lists_tasks_and_the_project_flag() -> None:
    done = robocore("--help")
    assert done.returncode == 0
    assert done.stdout.startswith("robocore [-p DIR] TASK")
    assert "-p STRING, --project=STRING" in done.stdout
    assert "--pty" in done.stdout
    for name in ("validate", "prepare-base", "stage", "build", "sync", "run", "shell", "connect", "schema", "init"):
        assert f"  {name} " in done.stdout


@pytest.mark.parametrize("args", [("fleet", "--help"), ("fleet", "rollout", "-h")])
def test_fleet_help_shows_the_commands_as_typed(args: tuple[str, ...]) -> None:
    """Not the task's internal flags (--verb, --version, --robot) but ``fleet rollout VERSION`` and the rest."""
    done = robocore(*args)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0].startswith("Usage: robocore [-p DIR] fleet COMMAND")
    for form in ("join", "rollout VERSION", "status", "rollback [ROBOT...]", "page --out DIR", "page --serve"):
        assert any(line.startswith(f"  {form}") for line in lines), form
    assert "--verb" not in done.stdout and "--version" not in done.stdout


@pytest.mark.parametrize("args", [("--help",), ("fleet", "--help"), ("fleet", "rollout", "-h")])
def test_help_into_a_reader_that_stopped_early_ends_without_a_traceback(args: tuple[str, ...]) -> None:
    """``robocore fleet --help | head -0``: the pipe is closed before robocore writes; status 1, nothing on stderr."""
    read, write = os.pipe()
    os.close(read)  # the reader is gone before robocore starts
    try:
        done = subprocess.run([sys.executable, "-m", "robocore", *args], stdout=write, stderr=subprocess.PIPE,
                              text=True, timeout=60)
    finally:
        os.close(write)
    assert done.returncode == 1
    assert done.stderr == ""


def test_version() -> None:
    from robocore import __version__

    done = robocore("--version")
    assert done.returncode == 0 and __version__ in done.stdout


def test_console_script_is_installed(good: Path) -> None:
    script = Path(sys.executable).with_name("robocore")
    assert script.exists(), "pip install -e . installs the robocore command next to python"
    done = subprocess.run([str(script), str(good), "validate"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr


def test_help_does_not_import_the_heavy_libraries() -> None:
    """robocore --help stays fast: pydantic, docker-py, copier and rich load only inside tasks."""
    code = (
        "import sys; from robocore.cli import main\n"
        "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
        "heavy = sorted(m for m in ('pydantic', 'docker', 'copier', 'rich', 'paramiko') if m in sys.modules)\n"
        "print('HEAVY=' + ','.join(heavy))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "HEAVY="


@pytest.mark.parametrize(
    "rest, expected",
    [
        (["init"], ["init", "--path=DIR"]),
        (["init", "--defaults"], ["init", "--path=DIR", "--defaults"]),
        (["init", "--path=OTHER"], ["init", "--path=OTHER"]),
        (["validate"], ["validate"]),
        ([], []),
    ],
)
def test_init_in_project(rest: list[str], expected: list[str]) -> None:
    assert init_in_project(rest, "DIR") == expected


def test_seed_form_init_creates_the_project_in_dir(tmp_path: Path) -> None:
    """`robocore <project_folder> init`, the folder before the task."""
    target = tmp_path / "myrobot"
    done = robocore(str(target), "init", "--defaults", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert (target / "robot.yaml").is_file()
    checked = robocore(str(target), "validate")
    assert checked.returncode == 0, checked.stderr


def test_a_tasks_own_f_flag_is_not_taken_for_invokes_config_file(tmp_path: Path) -> None:
    from robocore.cli import config_file_problem

    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    assert config_file_problem(["logs", "-f", "--tail", "0"]) is None
    assert config_file_problem(["build", "logs", "-f"]) is None
    assert "not a regular file" in (config_file_problem(["-f", str(fifo), "logs", "-f"]) or "")
    assert "cannot be read" in (config_file_problem(["--config=/nonexistent/x.yaml", "validate"]) or "")
