"""The hostile corpus (:mod:`corpus`) through robocore's own command line.

Each file goes through ``robocore validate``, ``stage --dry-run`` and ``sync --dry-run`` (and, when
it is refused, the real ``stage``), in this process through :func:`robocore.cli.main`. A refused
file exits 2 naming the expected ``file:line: key``; a dangerous but allowed one exits 0 with
exactly one warning line. No command may end in a traceback, and none may run what the file
smuggles in: every such value tries to create a marker file, and ``git`` on PATH is a stand-in that
records any run.
"""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from corpus import CASES, FOLDERS, Case

from robocore.cli import main

STAND_IN_GIT = "#!/bin/sh\ntouch '{ran}'\necho 'git stand-in: not a real git' >&2\nexit 1\n"


@dataclass(frozen=True)
class Sandbox:
    """A project folder, a marker the hostile values aim at, and a git stand-in that records runs."""

    root: Path
    project: Path
    mark: Path
    git_ran: Path
    outside: Path

    def write(self, case: Case) -> str:
        """Write ``case`` into the project (with its symlinks); returns the text written."""
        text = case.text.replace("{mark}", str(self.mark)).replace("{outside}", str(self.outside))
        (self.project / "robot.yaml").write_text(text, encoding="utf-8")
        for link, target in case.links.items():
            (self.project / link).parent.mkdir(parents=True, exist_ok=True)
            (self.project / link).symlink_to(self.outside / target)
        return text

    def smuggled(self) -> list[str]:
        """What ran that should not have: the marker, or git."""
        return [str(p) for p in (self.mark, self.git_ran) if p.exists()]


@pytest.fixture
def sandbox(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Sandbox:
    project = tmp_path / "robot"
    for folder in FOLDERS:
        (project / folder).mkdir(parents=True)
    outside = tmp_path / "outside"
    (outside / ".ssh").mkdir(parents=True)
    (outside / ".ssh" / "id_ed25519").write_text("PRIVATE KEY\n")
    (outside / "shared").mkdir()
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    box = Sandbox(tmp_path, project, tmp_path / "marker", tmp_path / "git-ran", outside)
    git = bin_dir / "git"
    git.write_text(STAND_IN_GIT.format(ran=box.git_ran))
    git.chmod(0o755)
    monkeypatch.setenv("PATH", f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '')}")
    monkeypatch.setenv("DOCKER_HOST", f"unix://{tmp_path / 'no-docker.sock'}")  # never the shared daemon
    monkeypatch.chdir(project)  # messages name ./robot.yaml as robot.yaml
    return box


def robocore(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, project: Path,
             *args: str) -> tuple[int, str]:
    """Run ``robocore -p PROJECT ARGS`` in this process; returns the exit code and stdout + stderr."""
    argv = ["-p", str(project), *args]
    monkeypatch.setattr(sys, "argv", ["robocore", *argv])  # robocore reads the step names (ssh warm-up)
    code = 0
    try:
        main(argv)
    except SystemExit as exit_:
        code = exit_.code if isinstance(exit_.code, int) else (0 if exit_.code is None else 1)
    captured = capsys.readouterr()
    return code, captured.out + captured.err


def _lines(output: str) -> list[str]:
    return output.splitlines()


def _error_line(where: str, output: str) -> str | None:
    return next((line for line in _lines(output) if line.startswith(f"error: {where}: ")), None)


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_hostile_file(case: Case, sandbox: Sandbox, capsys: pytest.CaptureFixture[str],
                      monkeypatch: pytest.MonkeyPatch) -> None:
    sandbox.write(case)
    code, output = robocore(capsys, monkeypatch, sandbox.project, "validate")
    outputs = [output]
    assert "Traceback" not in output, output
    if case.outcome == "rejected":
        assert code == 2, output
        assert _error_line(case.where, output), f"expected 'error: {case.where}: ...' in:\n{output[:3000]}"
        assert "warning:" not in output
    else:
        assert code == 0, output
        warnings = [line for line in _lines(output) if ": warning: " in line]
        assert len(warnings) == 1 and warnings[0].startswith(f"{case.where}: warning: "), output
        assert "ok — ROS 2" in output
    later = [("stage", "--dry-run"), ("sync", "--dry-run")]
    if case.outcome == "rejected":
        later.append(("stage",))  # the real one: refused at validation, before any git or Docker
    for args in later:
        code, output = robocore(capsys, monkeypatch, sandbox.project, *args)
        outputs.append(output)
        assert "Traceback" not in output, (args, output)
        if case.outcome == "rejected":
            assert code == 2 and _error_line(case.where, output), (args, output[:3000])
        else:  # no Docker daemon and nothing built here: a reported error, or success
            assert code == 0 or _lines(output)[0].startswith("error: "), (args, output)
    assert sandbox.smuggled() == []
    for line in (line for output in outputs for line in _lines(output)):
        assert len(line) < 500 and line.isprintable(), line


def test_the_corpus_is_large_and_covers_each_concern() -> None:
    ids = [c.id for c in CASES]
    assert len(ids) == len(set(ids)) >= 100
    assert len({c.text for c in CASES}) == len(CASES)
    rejected = [c for c in CASES if c.outcome == "rejected"]
    assert len(rejected) >= 100 and len(CASES) - len(rejected) >= 10
    for key in ("hosts[0].ip", "repositories[0].url", "repositories[0].version", "common_packages[0].repo",
                "pip_packages[0]", "apt_packages[0]", "base.image", "components[0].image", "registry",
                "mount_root", "devices[0]", "volumes[0]", "ports[0]", "environment"):
        assert any(key in c.where for c in rejected), key
    assert sum("{mark}" in c.text for c in CASES) >= 35


def test_the_marker_substitution_and_the_symlinks_are_real(sandbox: Sandbox) -> None:
    """A negative control for the corpus itself: the hostile values really aim at the marker, and a
    symlinked volume really leads outside the project."""
    case = next(c for c in CASES if c.id == "url-upload-pack")
    text = sandbox.write(case)
    assert f"--upload-pack=touch {sandbox.mark}" in text and "{mark}" not in text
    case = next(c for c in CASES if c.id == "volume-symlink-out-of-project")
    sandbox.write(case)
    assert (sandbox.project / "keys" / "id_ed25519").read_text() == "PRIVATE KEY\n"


def test_the_git_stand_in_would_notice_a_fetch(sandbox: Sandbox) -> None:
    """A negative control: robocore's git adapter, given a URL directly, runs the stand-in, which records it."""
    from robocore.adapters import vcs
    from robocore.errors import BuildError

    with pytest.raises(BuildError):
        vcs.fetch("https://example.invalid/x.git", None, sandbox.root / "checkout")
    assert sandbox.smuggled() == [str(sandbox.git_ran)]


def test_the_marker_would_be_noticed(sandbox: Sandbox) -> None:
    """A negative control: the command the values carry does create the marker when a shell runs it."""
    subprocess.run(["sh", "-c", f"touch {sandbox.mark}"], check=True)
    assert sandbox.smuggled() == [str(sandbox.mark)]


@pytest.mark.parametrize("case_id, args", [
    ("ip-ssh-option", ("validate",)),
    ("url-upload-pack", ("stage",)),
    ("pip-index-url", ("sync", "--dry-run")),
    ("privileged", ("validate",)),
])
def test_end_to_end_in_a_new_process(sandbox: Sandbox, case_id: str, args: tuple[str, ...]) -> None:
    case = next(c for c in CASES if c.id == case_id)
    sandbox.write(case)
    env = dict(os.environ)
    done = subprocess.run([sys.executable, "-m", "robocore", "-p", str(sandbox.project), *args],
                          capture_output=True, text=True, env=env, cwd=sandbox.project, timeout=120, check=False)
    output = done.stdout + done.stderr
    assert "Traceback" not in output
    if case.outcome == "rejected":
        assert done.returncode == 2 and _error_line(case.where, output), output
    else:
        assert done.returncode == 0 and f"{case.where}: warning: " in output, output
    assert sandbox.smuggled() == []
