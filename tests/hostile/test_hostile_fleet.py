"""A hostile fleet.yaml (from a clone, a pull request, a colleague): the corpus classes of robot.yaml, each
refused in one line naming fleet.yaml (with line and key where there is one), exit code 2, no traceback, at once.

File kinds (a link out of the project, a FIFO, a folder, a device), sizes, encodings, YAML bombs and values that
would be options or carry control characters. Each case runs ``robocore validate`` in a new process, as a user
would; the negative control is the same project with a good fleet.yaml, which validates.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from corpus import FLEET_ROBOT_YAML

from robocore.cli import main
from robocore.config import yamltext

ROBOT_YAML = FLEET_ROBOT_YAML
GOOD = """\
manager: {ip: 10.0.0.2}
robots:
  - name: r1
    hosts:
      main: {ip: 10.0.1.5}
"""


def project(tmp_path: Path) -> Path:
    root = tmp_path / "project"
    root.mkdir()
    (root / "robot.yaml").write_text(ROBOT_YAML)
    return root


def validate(root: Path, tmp_path: Path) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, DOCKER_HOST=f"unix://{tmp_path}/no-docker.sock")
    return subprocess.run([sys.executable, "-m", "robocore", "-p", str(root), "validate"], capture_output=True,
                          text=True, env=env, timeout=60, stdin=subprocess.DEVNULL, cwd=root)


def one_error(done: subprocess.CompletedProcess[str]) -> str:
    assert done.returncode == 2, done.stdout + done.stderr
    assert "Traceback" not in done.stderr
    errors = [line for line in done.stderr.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1, done.stderr
    assert all(len(line) < 500 and line.isprintable() for line in done.stderr.splitlines())
    return errors[0]


def test_negative_control_a_good_fleet_file_validates(tmp_path: Path) -> None:
    root = project(tmp_path)
    (root / "fleet.yaml").write_text(GOOD)
    done = validate(root, tmp_path)
    assert done.returncode == 0, done.stderr
    assert "fleet.yaml: ok — swarm, 1 robot(s), 1 wave(s): rest (1)" in done.stdout + done.stderr


@pytest.mark.parametrize("kind", ["link-out", "fifo", "folder", "device", "dangling"])
def test_a_fleet_file_that_leads_outside_or_is_not_a_file_is_one_line_at_once(tmp_path: Path, kind: str) -> None:
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "fleet.yaml").write_text(GOOD)
    root = project(tmp_path)
    fleet = root / "fleet.yaml"
    if kind == "link-out":
        fleet.symlink_to(outside / "fleet.yaml")
    elif kind == "fifo":
        os.mkfifo(fleet)  # a reader that opened it normally would wait for a writer for ever
    elif kind == "folder":
        fleet.mkdir()
    elif kind == "device":
        fleet.symlink_to("/dev/zero")
    else:
        fleet.symlink_to(tmp_path / "nowhere.yaml")
    line = one_error(validate(root, tmp_path))
    assert line.startswith("error: fleet.yaml: "), line
    assert any(words in line for words in ("outside the project", "not a regular file", "is not a file",
                                           "file not found")), line


CASES = {
    "too-big": (GOOD + "#" + "x" * yamltext.MAX_FILE_BYTES + "\n",
                "error: fleet.yaml: file is larger than 1 MB"),
    "latin-1": (GOOD.replace("r1", "r1") + "# caf\xe9\n", "error: fleet.yaml: not UTF-8 text"),
    "nul": (GOOD + "\x00\n", "error: fleet.yaml: not a text file (contains NUL bytes)"),
    "empty": ("# nothing\n", "error: fleet.yaml: file is empty; see 'robocore schema --fleet' for its keys"),
    "alias-bomb": ("a0: &a0 [x, x, x, x, x, x, x, x, x]\n" + "".join(
        f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]\n" for i in range(1, 10)),
        "error: fleet.yaml: document expands to more than"),
    "deep": ("robots: " + "[" * 10_000 + "\n", "error: fleet.yaml:1: YAML is nested more than 50 levels deep"),
    "octal": (GOOD + "    ros_domain_id: 017\n", "error: fleet.yaml:6: "),
    "ip-option": (GOOD.replace("10.0.1.5", '"-oProxyCommand=touch /tmp/x"'),
                  "error: fleet.yaml:5: robots[0].hosts.main.ip: must be an IP address or a host name, not an option"),
    "manager-option": (GOOD.replace("{ip: 10.0.0.2}", '{ip: 10.0.0.2, user: "-oProxyCommand=x"}'),
                       "error: fleet.yaml:1: manager.user: "),
    "registry-option": ("registry: --insecure\n" + GOOD, "error: fleet.yaml:1: registry: must be a registry"),
    "name-newline": (GOOD.replace("name: r1", 'name: "r1\\nerror: injected"'), "error: fleet.yaml:3: robots[0].name"),
    "host-key-escape": (GOOD.replace("main: {ip", '"main\\u001b[31m": {ip'),
                        "error: fleet.yaml:5: robots[0].hosts"),
    "label-control": (GOOD.replace("  - name: r1", '  - name: r1\n    labels: {site: "a\\tb"}'),
                      "error: fleet.yaml:4: robots[0].labels.site"),
    "topic-injection": (GOOD + "rollout:\n  health: {heard: [\"/chatter; rm -rf /\"]}\n",
                        "error: fleet.yaml:7: rollout.health.heard[0]"),
}


def validate_here(root: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> tuple[int, str]:
    """``robocore -p ROOT validate`` in this process (from inside ROOT): its exit code and its stderr."""
    monkeypatch.chdir(root)
    monkeypatch.setenv("DOCKER_HOST", f"unix://{root}/no-docker.sock")
    monkeypatch.setattr(sys, "argv", ["robocore", "-p", str(root), "validate"])
    code = 0
    try:
        main(["-p", str(root), "validate"])
    except SystemExit as exit_:
        code = exit_.code if isinstance(exit_.code, int) else (0 if exit_.code is None else 1)
    return code, capsys.readouterr().err


@pytest.mark.parametrize("case", sorted(CASES))
def test_hostile_fleet_content_is_one_line(tmp_path: Path, case: str, capsys: pytest.CaptureFixture[str],
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    text, start = CASES[case]
    root = project(tmp_path)
    data = text.encode("latin-1") if case == "latin-1" else text.encode("utf-8")
    (root / "fleet.yaml").write_bytes(data)
    code, err = validate_here(root, capsys, monkeypatch)
    assert code == 2 and "Traceback" not in err, err
    errors = [line for line in err.splitlines() if line.startswith("error: ")]
    assert errors and all(len(line) < 500 and line.isprintable() for line in err.splitlines())
    assert any(line.startswith(start) for line in errors), errors
