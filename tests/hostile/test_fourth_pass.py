"""The fourth hostile pass: nothing ``init`` makes is writable by others whatever the umask, and a lone surrogate in
a value (which no UTF-8 file or environment carries) is refused by validate in one line, never a crash of the
compose writer (whose own fallback is in tests/test_yaml_text.py's property test)."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest
from in_process import run_main

from robocore.files import NEVER


def init(cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    done = subprocess.run([sys.executable, "-m", "robocore", "init", *args, "--defaults"], cwd=cwd,
                          capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL,
                          preexec_fn=lambda: os.umask(0), env={**os.environ, "DOCKER_HOST": f"unix://{cwd}/no.sock"})
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    return done


def writable_by_others(root: Path) -> list[str]:
    found = [] if not stat.S_IMODE(os.lstat(root).st_mode) & NEVER else ["."]
    for here, folders, names in os.walk(root):
        for name in [*folders, *names]:
            path = Path(here) / name
            info = os.lstat(path)
            if not stat.S_ISLNK(info.st_mode) and stat.S_IMODE(info.st_mode) & NEVER:
                found.append(f"{path.relative_to(root)} {stat.S_IMODE(info.st_mode):04o}")
    return found


def test_init_under_umask_000_makes_nothing_others_may_write(tmp_path: Path) -> None:
    init(tmp_path, "robot")
    root = tmp_path / "robot"
    assert (root / "tasks.py").is_file() and (root / "components").is_dir()
    assert writable_by_others(root) == []


def test_init_into_an_existing_project_narrows_what_it_adds_and_leaves_the_users_files(tmp_path: Path) -> None:
    init(tmp_path, "robot")
    root = tmp_path / "robot"
    (root / "tasks.py").unlink()
    (root / "notes.txt").write_text("mine")
    os.chmod(root / "notes.txt", 0o664)  # the user's choice, kept
    init(tmp_path, "robot")
    assert (root / "tasks.py").is_file()
    assert writable_by_others(root) == ["notes.txt 0664"]


def test_the_fleet_pages_folders_are_not_writable_by_others_under_umask_000(tmp_path: Path) -> None:
    from robocore.commands import fleet_page
    from robocore.plan.fleet_page import FleetView

    old = os.umask(0)
    try:
        written = fleet_page.write_snapshot(FleetView(project="demo", taken="2026-12-07T00:00:00Z", robots=()),
                                            tmp_path / "pages" / "today")
    finally:
        os.umask(old)
    assert written.is_file()
    assert writable_by_others(tmp_path / "pages") == []


def test_the_graph_tests_build_lock_is_private_and_never_through_a_link(tmp_path: Path) -> None:
    from robocore.project import ProjectFolder
    from robocore.testing.bringup import build_lock

    project = ProjectFolder(root=tmp_path / "robot")  # only its folders are used
    project.root.mkdir()
    old = os.umask(0)
    try:
        with build_lock(project):  # type: ignore[arg-type]
            pass
    finally:
        os.umask(old)
    assert writable_by_others(project.root) == [] and project.build_lock.is_file()
    project.build_lock.unlink()
    project.build_lock.symlink_to(tmp_path / "elsewhere")
    with pytest.raises(OSError), build_lock(project):  # type: ignore[arg-type]
        pass
    assert not (tmp_path / "elsewhere").exists()


ROBOT_YAML = """\
ros_distro: jazzy
hosts:
  - {name: main, ip: 192.168.1.10}
components:
  - name: talker
    image: "ros:jazzy"
    runs_on: main
"""


@pytest.mark.parametrize("file, text, where", [
    ("robot.yaml", ROBOT_YAML + '    environment: {X: "a\\udc80b"}\n',
     "robot.yaml:8: components[0].environment.X: "),  # the case
    ("robot.yaml", ROBOT_YAML + '    environment:\n      "\\ud800": x\n',
     "robot.yaml:9: components[0].environment.\\ud800: "),
    ("robot.yaml", ROBOT_YAML + '    launch_args: "x:=\\U0000dfff"\n', "robot.yaml:8: components[0].launch_args: "),
    ("fleet.yaml", 'manager: {ip: 10.0.0.2}\nregistry: 10.0.0.2:5000\nrobots:\n  - name: r1\n'
     '    labels: {site: "\\udc80"}\n    hosts: {main: {ip: 10.0.1.5}}\n', "fleet.yaml:5: robots[0].labels.site: "),
])
def test_a_lone_surrogate_is_one_line_at_validate(file: str, text: str, where: str, tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str],
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    root = tmp_path / "project"
    root.mkdir()
    (root / "robot.yaml").write_text(ROBOT_YAML if file == "fleet.yaml" else text)
    if file == "fleet.yaml":
        (root / "fleet.yaml").write_text(text)
    monkeypatch.chdir(root)
    code, _, err = run_main(["-p", str(root), "validate"], capsys)
    errors = [line for line in err.splitlines() if line.startswith("error: ")]
    assert code == 2 and "Traceback" not in err and len(errors) == 1, err
    assert errors[0].startswith(f"error: {where}") and "lone surrogate" in errors[0], errors
    task = ["fleet", "status", "--dry-run"] if file == "fleet.yaml" else ["run", "--dry-run"]
    code, _, err = run_main(["-p", str(root), *task], capsys)  # no task gets past it
    assert code == 2 and "Traceback" not in err


def test_state_records_are_read_bounded_never_through_a_link(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every record robocore reads is bounded: a run history, a sync or build state past the bound is read as none
    (as a broken one is), and a build state reached through a link is never read (it labelled the container)."""
    from robocore.commands.support import state
    from robocore.config.model import Robot
    from robocore.plan.containers import host_specs
    from robocore.project import Project

    robot = Robot.model_validate({"ros_distro": "jazzy", "hosts": [{"name": "dev", "ip": "127.0.0.1"}],
                                  "components": [{"name": "b", "runs_on": "dev", "folder": "b"}]})
    project = Project(root=tmp_path, robot=robot)
    dev = project.host("dev")
    state.record_run(project, dev, "v1")
    assert [run["tag"] for run in state.history(project, "dev")] == ["v1"]  # control: read within the bound
    history = project.history_file("dev")
    history.write_text(history.read_text() + " " * 2000)
    monkeypatch.setattr(state, "MAX_STATE_RECORD_BYTES", 1000, raising=False)
    assert state.history(project, "dev") == []
    monkeypatch.undo()

    def build_label() -> list[str]:
        return [v for s in state.with_local_build(project, dev, host_specs(project, "dev"))
                for k, v in s.extra_labels if k == state.LABEL_BUILD]

    state.write_build_state(project.build_state_file("b"), {"packages": {"p": "h"}})
    assert build_label()  # control: the build's own state labels it
    outside = tmp_path / "outside.json"
    outside.write_text('{"packages": {"p": "h"}}')
    project.build_state_file("b").unlink()
    project.build_state_file("b").symlink_to(outside)
    assert build_label() == []
