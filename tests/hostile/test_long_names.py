"""Names the file system refuses (too long, a NUL byte) are one problem line, never a traceback."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from robocore.config.loader import parse_robot_text
from robocore.errors import ConfigError
from robocore.files import path_kind

LONG = "a" * 300  # over NAME_MAX (255) on Linux file systems


def test_path_kind_never_raises(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("x")
    assert path_kind(tmp_path) == ("dir", "")
    assert path_kind(tmp_path / "f") == ("file", "")
    assert path_kind(tmp_path / "nothing") == ("missing", "")
    assert path_kind(tmp_path / "f" / "below-a-file") == ("missing", "")
    assert path_kind(tmp_path / LONG) == ("unusable", "File name too long")
    assert path_kind(tmp_path / "a\0b")[0] == "unusable"


def test_a_component_folder_name_too_long_is_one_problem(tmp_path: Path) -> None:
    text = ("ros_distro: jazzy\nhosts:\n  - {name: dev, ip: 127.0.0.1}\n"
            f"components:\n  - {{name: c, runs_on: dev, folder: {LONG}}}\n")
    with pytest.raises(ConfigError) as caught:
        parse_robot_text(text, file="robot.yaml", project=tmp_path)
    (line,) = caught.value.lines()
    assert line.startswith("robot.yaml:5: components[0].folder: 'aaaa"), line
    assert line.endswith("... (300 characters) cannot be used as a folder: File name too long"), line  # shortened


def test_a_project_folder_name_too_long_is_one_line_and_exit_2(tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, "-m", "robocore", "-p", str(tmp_path / LONG), "validate"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    path = f"error: {tmp_path / LONG}:"
    assert proc.stderr.strip().splitlines() == [  # the path cut to 200 characters, with its length
        f"error: {path[7:207]}... ({len(path) - 7:,} characters) cannot be used as a project folder: "
        "File name too long"]
