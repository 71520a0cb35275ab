"""The export folder of ``export kubernetes`` (the fourth hostile pass): its record
``.robocore-written`` travels with the GitOps repository, so it decides nothing it could not decide alone. Only names
export writes are removed (never a dot-part), a file the record does not list is never replaced, the record is
believed only when private and bounded, a hard link is replaced by a rename, and every refusal is one line, exit 2,
by a dry run too, before any warning.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from corpus import FLEET_ROBOT_YAML
from in_process import run_main

from robocore import export_folder
from robocore.files import WRITTEN_RECORD

ROBOT_YAML = FLEET_ROBOT_YAML
FLEET_YAML = "engine: kubernetes\nrobots:\n  - {name: r1, hosts: {main: {ip: 10.0.1.5}}}\n"


@pytest.fixture
def root(tmp_path: Path) -> Path:
    project = tmp_path / "project"
    project.mkdir()
    (project / "robot.yaml").write_text(ROBOT_YAML)
    (project / "fleet.yaml").write_text(FLEET_YAML)
    return project


def export(root: Path, folder: Path | str, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
           *extra: str) -> tuple[int, list[str], str]:
    monkeypatch.chdir(root)
    code, out, err = run_main(["-p", str(root), "export", "kubernetes", str(folder), "--tag", "v1", *extra], capsys)
    assert "Traceback" not in err
    assert all(line.isprintable() for line in (out + err).splitlines())
    return code, [line for line in err.splitlines() if line.startswith("error: ")], out + err


def refused(result: tuple[int, list[str], str], says: str) -> str:
    code, errors, said = result
    assert code == 2 and len(errors) == 1 and says in errors[0], said
    assert "warning:" not in said, said  # the refusal comes first, alone
    return errors[0]


# --- item 5: what the record may make an export remove or replace --------------------------------------------------

@pytest.mark.parametrize("planted", [
    [".git/config", "README"],  # the case
    ["../outside.yaml", "robots/../../outside2.yaml", "bases/x/.hidden.yaml", ".github/workflows/ci.yaml",
     "notes.txt", "/etc/passwd"],
    # the user's own files in the GitOps repository, of the kinds export writes but at names it never writes
    ["ci/deploy.yaml", "setup.py", "docs/conf.py", "values.yaml", "robots/r1/extra/patch.yaml", "bases/m/x/y.yaml",
     "bases/m/dds/x.yaml", "argocd/other.yaml"],
])
def test_a_planted_record_removes_only_names_export_writes(planted: list[str], root: Path, tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str],
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "out"
    assert export(root, out, capsys, monkeypatch)[0] == 0
    keep = {}
    for name in planted:
        path = out / name if not name.startswith("/") else Path(name)
        if not name.startswith("/"):
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(f"user's {name}\n")
        keep[path] = path.read_bytes()
    record = out / WRITTEN_RECORD
    record.write_text(record.read_text() + "".join(f"{name}\n" for name in planted) + "robots/old/namespace.yaml\n")
    (out / "robots" / "old").mkdir()
    (out / "robots" / "old" / "namespace.yaml").write_text("stale\n")  # a name export writes: removed (control)
    assert export(root, out, capsys, monkeypatch)[0] == 0
    assert all(path.read_bytes() == data for path, data in keep.items())
    assert not (out / "robots" / "old").exists()


def test_every_name_an_export_writes_is_one_its_record_keeps(root: Path, tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str],
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """The names a record is read for (export_folder.EXPORT_NAME) cover every file an export writes (overlays with
    a domain, DDS profiles, the health gate's scripts, the GitOps files), so a file export wrote is always removed
    when it is no longer wanted."""
    (root / "fleet.yaml").write_text("engine: kubernetes\nrobots:\n  - {name: r1, hosts: {main: {ip: 10.0.1.5}}}\n"
                                     "  - {name: r-2, ros_domain_id: 7, hosts: {main: {ip: 10.0.1.6}}}\n")
    out = tmp_path / "out"
    assert export(root, out, capsys, monkeypatch)[0] == 0
    written = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file() and p.name != WRITTEN_RECORD)
    assert {"robots/r-2/domain.yaml", "bases/project/health/probe.py", "bases/project/dds/client.xml",
            "argocd/applicationset.yaml", "fleet.yaml", "kustomization.yaml"} <= set(written), written  # control
    assert export_folder.record_names((out / WRITTEN_RECORD).read_bytes()) == written


@pytest.mark.parametrize("name, record", [
    ("kustomization.yaml", ""),  # the case: an empty record
    ("robots/r1/namespace.yaml", "fleet.yaml\n"),  # a record that lists other names
])
def test_a_file_the_record_does_not_list_is_never_replaced(name: str, record: str, root: Path, tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str],
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "out"
    (out / name).parent.mkdir(parents=True)
    (out / name).write_text("the user's own\n")
    (out / WRITTEN_RECORD).write_text(record)
    (out / WRITTEN_RECORD).chmod(0o600)
    line = refused(export(root, out, capsys, monkeypatch), "is a file robocore did not write")
    assert name in line
    assert (out / name).read_text() == "the user's own\n"
    line = refused(export(root, out, capsys, monkeypatch, "--dry-run"), "is a file robocore did not write")


@pytest.mark.parametrize("what", ["folder", "fifo"])
@pytest.mark.parametrize("dry", [False, True])
def test_a_listed_name_that_is_no_file_is_refused_before_anything_is_written(
        what: str, dry: bool, root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "out"
    assert export(root, out, capsys, monkeypatch)[0] == 0
    target = out / "robots" / "r1" / "namespace.yaml"  # a name the record lists
    target.unlink()
    if what == "folder":
        target.mkdir()
        (target / "mine").write_text("the user's\n")
    else:
        os.mkfifo(target)
    (root / "fleet.yaml").write_text(FLEET_YAML.replace("r1", "r0") + "  - {name: r1, hosts: {main: {ip: 10.0.1.6}}}\n")
    before = sorted((str(p), p.lstat().st_mtime_ns) for p in out.rglob("*"))
    line = refused(export(root, out, capsys, monkeypatch, *(["--dry-run"] if dry else [])), "is not a regular file")
    assert "robots/r1/namespace.yaml" in line
    assert sorted((str(p), p.lstat().st_mtime_ns) for p in out.rglob("*")) == before  # nothing written, by either


@pytest.mark.parametrize("how", ["group-writable", "world-writable", "link", "too-big", "folder", "other-user"])
def test_a_record_that_cannot_be_believed_refuses_the_export(how: str, root: Path, tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str],
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "out"
    assert export(root, out, capsys, monkeypatch)[0] == 0
    record = out / WRITTEN_RECORD
    if how == "group-writable":
        record.chmod(0o660)
    elif how == "world-writable":
        record.chmod(0o606)
    elif how == "link":
        (tmp_path / "elsewhere").write_text(record.read_text())
        record.unlink()
        record.symlink_to(tmp_path / "elsewhere")
    elif how == "too-big":
        monkeypatch.setattr(export_folder, "MAX_RECORD_BYTES", 1000)
        record.write_text("x.yaml\n" * 200)
    elif how == "folder":
        record.unlink()
        record.mkdir()
    else:
        if os.geteuid() != 0:
            pytest.skip("giving a file to another user needs root")
        os.chown(record, 65534, 65534)
    before = sorted(p.name for p in out.rglob("*"))
    refused(export(root, out, capsys, monkeypatch), WRITTEN_RECORD)
    assert sorted(p.name for p in out.rglob("*")) == before


# --- item 8: what used to end in a traceback ------------------------------------------------------------------------

@pytest.mark.parametrize("junk", [b"robots/x\x00.yaml\n", b"\xff\xfe\n", b"a\rb.yaml\n" + b"\x1b[2J.yaml\n"])
def test_a_nul_or_junk_in_the_record_is_ignored_and_later_exports_work(junk: bytes, root: Path, tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str],
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "out"
    assert export(root, out, capsys, monkeypatch)[0] == 0
    record = out / WRITTEN_RECORD
    record.write_bytes(record.read_bytes() + junk)
    assert export(root, out, capsys, monkeypatch)[0] == 0
    assert export(root, out, capsys, monkeypatch)[0] == 0
    assert b"\x00" not in record.read_bytes()


@pytest.mark.parametrize("folder", ["x" * 300, "/proc/robocore-export", "/proc/self/fd/robocore", "deep/" + "y" * 300],
                         ids=["name-too-long", "under-proc", "under-proc-fd", "part-too-long-below"])
@pytest.mark.parametrize("dry", [False, True])
def test_an_export_folder_that_cannot_be_one_is_one_line(folder: str, dry: bool, root: Path,
                                                         capsys: pytest.CaptureFixture[str],
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    refused(export(root, folder, capsys, monkeypatch, *(["--dry-run"] if dry else [])), "")


# --- item 11: a component whose file would be the base's own -------------------------------------------------------

@pytest.mark.parametrize("name", ["kustomization", "Kustomization", "health", "HEALTH", "discovery-services"])
def test_a_component_named_like_the_bases_own_file_is_refused(name: str, root: Path, tmp_path: Path,
                                                              capsys: pytest.CaptureFixture[str],
                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    (root / "robot.yaml").write_text(ROBOT_YAML + f"  - {{name: {name}, image: 'ros:jazzy', runs_on: main}}\n")
    code, errors, said = export(root, tmp_path / "out", capsys, monkeypatch)
    assert code == 2 and len(errors) == 1 and errors[0].startswith("error: robot.yaml:7: components[1].name: "), said
    assert not (tmp_path / "out").exists()


def test_every_file_of_a_base_that_is_no_components_has_a_name_no_component_may_take(
        root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """The base folder's own files, read from a real export (with DDS profiles and the health gate), are each refused
    as a component's name: a new file of the base cannot silently take a component's place."""
    out = tmp_path / "out"
    assert export(root, out, capsys, monkeypatch)[0] == 0
    (base,) = (out / "bases").iterdir()
    own = sorted(p.stem for p in base.glob("*.yaml") if p.stem != "talker")
    assert {"kustomization", "health"} <= set(own), own  # control: the files the refusal must cover are there
    for stem in own:
        (root / "robot.yaml").write_text(ROBOT_YAML + f"  - {{name: {stem}, image: 'ros:jazzy', runs_on: main}}\n")
        code, errors, said = export(root, tmp_path / f"out-{stem}", capsys, monkeypatch)
        assert code == 2 and len(errors) == 1 and "components[1].name" in errors[0], (stem, said)


# --- item 12: a hard link is replaced, never changed in place ------------------------------------------------------

@pytest.mark.parametrize("same_content", [True, False])
def test_a_hard_link_in_the_export_folder_is_replaced_by_a_rename(same_content: bool, root: Path, tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str],
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "out"
    assert export(root, out, capsys, monkeypatch)[0] == 0
    inside = out / "fleet.yaml"
    outside = tmp_path / "precious.yaml"
    outside.write_bytes(inside.read_bytes() if same_content else b"precious\n")
    outside.chmod(0o644)
    inside.unlink()
    os.link(outside, inside)
    before = outside.read_bytes()
    assert export(root, out, capsys, monkeypatch)[0] == 0
    assert outside.stat().st_mode & 0o777 == 0o644 and outside.read_bytes() == before
    assert inside.stat().st_ino != outside.stat().st_ino and inside.stat().st_nlink == 1


# --- minor: dry runs, forged lines, the order of the lines ---------------------------------------------------------

def test_a_dry_run_into_a_folder_the_export_refuses_is_refused(root: Path, tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str],
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "mine.txt").write_text("x")
    line = refused(export(root, out, capsys, monkeypatch, "--dry-run"), "holds files robocore did not write")
    assert "would write" not in line
    refused(export(root, out, capsys, monkeypatch), "holds files robocore did not write")  # the same as the real one
    (tmp_path / "empty").mkdir()
    code, _, said = export(root, tmp_path / "empty", capsys, monkeypatch, "--dry-run")  # negative control
    assert code == 0 and "would write" in said


@pytest.mark.parametrize("dry", [False, True])
def test_a_newline_in_the_folders_name_forges_no_line(dry: bool, root: Path, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str],
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    folder = tmp_path / "out\nerror: forged"
    code, _, said = export(root, folder, capsys, monkeypatch, *(["--dry-run"] if dry else []))
    assert code == 0, said
    assert not any(line.startswith("error: forged") for line in said.splitlines()), said
    assert "out\\nerror: forged" in said
