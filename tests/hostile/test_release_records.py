"""Release records (``.robocore/releases/V.json``) are believed only as robocore's own records are (the fourth
hostile pass): this user's, writable by no one else, in a folder likewise, naming only the fleet's registry and each
image's own repository. Anything else is one line naming the record (and its key), exit 2, no traceback, nothing run.

Each case runs ``export kubernetes`` (and ``fleet rollout --dry-run``) in this process, as a user would.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from in_process import run_main

from robocore.plan.fleet_release import ReleaseRecord

DIGEST = "sha256:" + "ab" * 32
ROBOT_YAML = """\
ros_distro: jazzy
image_prefix: bot-
registry: 10.0.0.2:5000
hosts:
  - {name: main, ip: 192.168.1.10}
components:
  - {name: talker, image: "ros:jazzy", runs_on: main}
  - {name: listener, image: "ros:jazzy", runs_on: main}
"""
FLEET_YAML = "manager: {ip: 10.0.0.2}\nrobots:\n  - {name: r1, hosts: {main: {ip: 10.0.1.5}}}\n"
REGISTRY = "10.0.0.2:5000"


def record(**change: str) -> dict[str, object]:
    refs = {"talker": f"{REGISTRY}/bot-talker@{DIGEST}", "listener": f"{REGISTRY}/bot-listener@{DIGEST}",
            "base": f"{REGISTRY}/bot-base@{DIGEST}", **change}
    return json.loads(ReleaseRecord(version="v1", registry=change.get("registry", REGISTRY),
                                    components={"talker": {"amd64": refs["talker"]},
                                                "listener": {"amd64": refs["listener"]}},
                                    base={"amd64": refs["base"]}).to_json())


def project(tmp_path: Path, content: dict[str, object] | str | None = None) -> Path:
    root = tmp_path / "project"
    (root / ".robocore" / "releases").mkdir(parents=True)
    (root / "robot.yaml").write_text(ROBOT_YAML)
    (root / "fleet.yaml").write_text(FLEET_YAML)
    if content is not None:
        path = root / ".robocore" / "releases" / "v1.json"
        path.write_text(content if isinstance(content, str) else json.dumps(content))
        path.chmod(0o600)
    return root


def run(root: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
        *argv: str) -> tuple[int, list[str], str]:
    monkeypatch.chdir(root)
    code, out, err = run_main(["-p", str(root), *argv], capsys)
    assert "Traceback" not in err
    assert all(line.isprintable() and len(line) < 1000 for line in err.splitlines())
    return code, [line for line in err.splitlines() if line.startswith("error: ")], out + err


EXPORT = ("export", "kubernetes", "out", "--tag", "v1")
ROLLOUT = ("fleet", "rollout", "v1", "--dry-run")

NAMES_ELSEWHERE = {
    # the cases: another registry, Docker Hub
    "other-registry": (record(talker=f"evil.example:5000/bot-talker@{DIGEST}"), "components.talker.amd64",
                       "outside the fleet's registry"),
    "docker-hub": (record(base=f"docker.io/library/busybox@{DIGEST}"), "base.amd64", "outside the fleet's registry"),
    # variants: another component's image, a look-alike registry, the record's own registry key
    "another-components-image": (record(talker=f"{REGISTRY}/bot-listener@{DIGEST}"), "components.talker.amd64",
                                 "not that image's repository"),
    "registry-prefix-look-alike": (record(listener=f"{REGISTRY}0/bot-listener@{DIGEST}"),
                                   "components.listener.amd64", "outside the fleet's registry"),
    "record-registry": (record(registry="evil.example:5000"), "registry", "not the fleet's registry"),
}


@pytest.mark.parametrize("argv", [EXPORT, ROLLOUT], ids=["export", "rollout"])
@pytest.mark.parametrize("case", sorted(NAMES_ELSEWHERE))
def test_a_record_naming_images_elsewhere_is_refused(case: str, argv: tuple[str, ...], tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str],
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    content, key, says = NAMES_ELSEWHERE[case]
    root = project(tmp_path, content)
    code, errors, said = run(root, capsys, monkeypatch, *argv)
    assert code == 2, said
    assert any(line.startswith(f"error: {root}/.robocore/releases/v1.json: {key}: ") and says in line
               for line in errors), errors
    assert not (root / "out").exists()


@pytest.mark.parametrize("argv", [EXPORT, ROLLOUT], ids=["export", "rollout"])
def test_negative_control_a_good_record_is_believed(argv: tuple[str, ...], tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str],
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    root = project(tmp_path, record())
    code, errors, said = run(root, capsys, monkeypatch, *argv)
    assert code == 0 and not errors, said


@pytest.mark.parametrize("mode", [0o666, 0o620, 0o602])
def test_a_record_others_may_write_is_not_believed(mode: int, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    root = project(tmp_path, record())
    (root / ".robocore" / "releases" / "v1.json").chmod(mode)
    code, errors, said = run(root, capsys, monkeypatch, *EXPORT)
    assert code == 2 and len(errors) == 1 and "may be written by group or others" in errors[0], said


@pytest.mark.skipif(os.geteuid() != 0, reason="giving a file to another user needs root")
@pytest.mark.parametrize("what", ["record", "folder"])
def test_a_record_of_another_user_is_not_believed(what: str, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    root = project(tmp_path, record())
    target = root / ".robocore" / "releases"
    os.chown(target / "v1.json" if what == "record" else target, 65534, 65534)
    code, errors, said = run(root, capsys, monkeypatch, *EXPORT)
    assert code == 2 and len(errors) == 1 and "belongs to another user (uid 65534)" in errors[0], said


def test_a_widened_releases_folder_is_narrowed(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    root = project(tmp_path, record())
    folder = root / ".robocore" / "releases"
    folder.chmod(0o777)
    code, _, said = run(root, capsys, monkeypatch, *EXPORT)
    assert code == 0, said
    assert folder.stat().st_mode & 0o022 == 0


# --- item 8: records that used to end in a traceback ----------------------------------------------------------------

BROKEN = {
    "a-folder": (None, "a folder"),
    "5000-digit-number": ('{"format": 1, "version": "v1", "n": ' + "9" * 5000 + "}", "a number too long to read"),
    "5000-digit-format": ('{"format": ' + "1" * 5000 + "}", "a number too long to read"),
    "latin-1": (None, "not UTF-8"),
    "fifo": (None, "not a regular file"),
    # keys that would reach an error line: a newline in an arch or a component's name forges a line of its own
    "newline-in-arch": (json.dumps({**record(), "components": {"talker": {
        "amd64\nerror: forged": f"evil.example/x@{DIGEST}"}}}), "named as in robot.yaml and images by arch"),
    "escape-in-component": (json.dumps({**record(), "components": {"lis\x1b[2Jtener\n": {
        "amd64": f"{REGISTRY}/bot-listener@{DIGEST}"}}}), "named as in robot.yaml"),
    "unknown-arch": (json.dumps({**record(), "base": {"riscv64": f"{REGISTRY}/bot-base@{DIGEST}"}}), "by arch"),
}


@pytest.mark.parametrize("argv", [EXPORT, ROLLOUT], ids=["export", "rollout"])
@pytest.mark.parametrize("case", sorted(BROKEN))
def test_a_broken_record_is_one_line(case: str, argv: tuple[str, ...], tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    text, says = BROKEN[case]
    root = project(tmp_path, text)
    path = root / ".robocore" / "releases" / "v1.json"
    if case == "a-folder":
        path.mkdir()
    elif case == "latin-1":
        path.write_bytes(b'{"caf\xe9": 1}')
        path.chmod(0o600)
    elif case == "fifo":
        os.mkfifo(path, 0o600)
    code, errors, said = run(root, capsys, monkeypatch, *argv)
    assert code == 2 and len(errors) == 1, said
    assert errors[0].startswith(f"error: {path}: ") and says in errors[0], errors
