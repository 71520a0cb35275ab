"""A cloned project whose ``.robocore/compose`` is a symlink to a folder outside, staged for real.

The built demo project is committed to a git repository with ``.robocore/compose`` a symlink to a folder
outside it (holding a canary, a file named as the host's compose file and a record of written files naming
both), then cloned: git recreates the link. ``robocore stage`` on the clone (real Docker, the demo's
images) must refuse in one line naming the link, without a traceback, and leave the outside folder as it was.
Negative control: with the link removed the same clone stages, and its compose file is written inside the
project (so the check above was on a path stage really writes).
"""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

import pytest
import yaml
from conftest import RobocoreCli

from robocore.files import WRITTEN_RECORD

pytestmark = pytest.mark.docker


def git(cwd: Path, *args: str) -> None:
    subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@t", *args], cwd=cwd, check=True,
                   capture_output=True)


def test_stage_refuses_a_compose_folder_linked_outside_and_the_canary_survives(
        project_copies: Any, run_robocore: RobocoreCli, tmp_path: Path) -> None:
    origin = project_copies("links")
    host = yaml.safe_load((origin / "robot.yaml").read_text())["hosts"][0]["name"]
    outside = tmp_path / "outside"
    outside.mkdir()
    files = {"canary": b"keys live here\n", f"{host}.yaml": b"not robocore's\n", WRITTEN_RECORD: b"canary\n"}
    for name, data in files.items():
        (outside / name).write_bytes(data)
    (origin / ".robocore" / "compose").mkdir(parents=True, exist_ok=True)
    (origin / ".robocore" / "compose").rmdir()
    (origin / ".robocore" / "compose").symlink_to(outside)
    git(origin, "init", "-q")
    git(origin, "add", "-f", "robot.yaml", "components", ".robocore/compose")
    git(origin, "commit", "-q", "-m", "hostile")
    clone = tmp_path / "clone" / origin.name  # the same folder name: the same project, images and containers
    clone.parent.mkdir()
    git(tmp_path, "clone", "-q", str(origin), str(clone))
    assert (clone / ".robocore" / "compose").is_symlink()
    before = {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in outside.iterdir()}

    done = run_robocore(clone, "stage", check=False, timeout=300)
    assert done.returncode == 2, done.stdout + done.stderr
    assert "Traceback" not in done.stderr
    first, *rest = done.stderr.splitlines()
    assert first.startswith("error: .robocore/compose: a symlink") and "where robocore writes" in first, first
    assert all(line.startswith("hint:") for line in rest)
    assert {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in outside.iterdir()} == before

    # negative control: the same clone without the link stages (the demo's images are cached) and writes inside
    (clone / ".robocore" / "compose").unlink()
    for install in (origin / ".robocore" / "build").glob("*/install"):  # the build trees git does not carry
        (clone / ".robocore" / "build" / install.parent.name).mkdir(parents=True, exist_ok=True)
    staged = run_robocore(clone, "stage", "--quiet", check=False, timeout=900)
    assert staged.returncode == 0, staged.stdout + staged.stderr
    assert (clone / ".robocore" / "compose" / f"{host}.yaml").is_file()
    assert {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in outside.iterdir()} == before
