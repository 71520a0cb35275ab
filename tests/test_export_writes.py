"""robocore.export_writes.write_files: write_atomic's result (modes, refusals, unchanged files kept, links never
followed, hard links replaced) through one descriptor per folder, for the export folder's tens of thousands of files."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from robocore import export_writes
from robocore.errors import UnsafePath
from robocore.files import NEVER, PRIVATE, UMASK, write_atomic

FILES = {"kustomization.yaml": "root\n", "robots/r0/namespace.yaml": "ns r0\n", "robots/r1/namespace.yaml": "ns r1\n",
         "bases/m/a.yaml": "a\n", "bases/m/dds/p.xml": b"<x/>\n", "argocd/applicationset.yaml": "é\n"}


def tree(folder: Path) -> dict[str, tuple[bytes, int]]:
    """Every file and folder under ``folder``: content (files) and mode."""
    return {str(p.relative_to(folder)): (p.read_bytes() if p.is_file() else b"", stat.S_IMODE(p.lstat().st_mode))
            for p in sorted(folder.rglob("*"))}


def atomic(folder: Path, files: dict[str, str | bytes], mode: int | None) -> None:
    """What write_tree did before: write_atomic of each file (its folder made private when mode is PRIVATE)."""
    for name, content in files.items():
        write_atomic(folder / name, content, mode=mode, durable=False)


@pytest.mark.parametrize("mode", [PRIVATE, None, 0o640])
def test_the_same_files_and_modes_as_write_atomic(mode: int | None, tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    export_writes.write_files(tmp_path / "a", FILES, mode)
    atomic(tmp_path / "b", FILES, mode)
    written = tree(tmp_path / "a")
    assert written["robots/r0/namespace.yaml"][0] == b"ns r0\n"
    assert written["argocd/applicationset.yaml"][0] == "é\n".encode()
    assert written == tree(tmp_path / "b")
    if mode == PRIVATE:  # each file's own folder private, the folders above it the umask's (as make_folder does)
        assert written["robots/r0"][1] == 0o700 and written["robots"][1] == 0o777 & ~UMASK & ~NEVER


def test_modes_whatever_the_umask(tmp_path: Path) -> None:
    old = os.umask(0o277)
    try:
        export_writes.write_files(tmp_path, FILES, PRIVATE)
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "robots/r0/namespace.yaml").stat().st_mode) == PRIVATE


def test_an_unchanged_file_is_kept_and_its_mode_narrowed_a_changed_one_replaced(tmp_path: Path) -> None:
    export_writes.write_files(tmp_path, FILES, PRIVATE)
    same, other = tmp_path / "robots/r0/namespace.yaml", tmp_path / "robots/r1/namespace.yaml"
    same.chmod(0o644)
    inodes = same.stat().st_ino, other.stat().st_ino
    export_writes.write_files(tmp_path, {**FILES, "robots/r1/namespace.yaml": "changed\n"}, PRIVATE)
    assert same.stat().st_ino == inodes[0] and stat.S_IMODE(same.stat().st_mode) == PRIVATE
    assert other.stat().st_ino != inodes[1] and other.read_text() == "changed\n"
    assert not [p for p in tmp_path.rglob(".*.tmp")]


def test_a_hard_linked_file_is_replaced_never_changed(tmp_path: Path) -> None:
    (tmp_path / "out").mkdir()
    export_writes.write_files(tmp_path / "out", FILES, PRIVATE)
    outside = tmp_path / "outside"
    outside.write_text("ns r0\n")
    outside.chmod(0o644)
    inside = tmp_path / "out/robots/r0/namespace.yaml"
    inside.unlink()
    os.link(outside, inside)
    export_writes.write_files(tmp_path / "out", FILES, PRIVATE)
    assert stat.S_IMODE(outside.stat().st_mode) == 0o644 and outside.stat().st_nlink == 1
    assert inside.read_text() == "ns r0\n" and inside.stat().st_ino != outside.stat().st_ino


@pytest.mark.parametrize("where", ["robots", "robots/r0", "robots/r0/namespace.yaml"])
def test_a_link_on_the_way_is_refused_and_nothing_written_through_it(where: str, tmp_path: Path) -> None:
    out, elsewhere = tmp_path / "out", tmp_path / "elsewhere"
    out.mkdir()
    elsewhere.mkdir()
    (out / where).parent.mkdir(parents=True, exist_ok=True)
    (out / where).symlink_to(elsewhere)
    with pytest.raises(UnsafePath, match=r"a symlink|is not a regular file"):
        export_writes.write_files(out, FILES, PRIVATE)
    assert list(elsewhere.iterdir()) == []


def test_a_file_where_a_folder_goes_is_refused_in_one_line(tmp_path: Path) -> None:
    (tmp_path / "robots").write_text("x")
    with pytest.raises(UnsafePath, match="is not a folder"):
        export_writes.write_files(tmp_path, FILES, PRIVATE)


def test_a_folder_where_a_file_goes_is_refused(tmp_path: Path) -> None:
    (tmp_path / "kustomization.yaml").mkdir()
    with pytest.raises(UnsafePath, match="is not a regular file"):
        export_writes.write_files(tmp_path, FILES, PRIVATE)


def test_under_a_state_folder_a_folder_others_may_write_is_narrowed_as_make_folder_does(tmp_path: Path) -> None:
    out = tmp_path / ".robocore" / "out"
    (out / "robots" / "r0").mkdir(parents=True)
    (out / "robots").chmod(0o777)
    export_writes.write_files(out, FILES, PRIVATE)
    assert stat.S_IMODE((out / "robots").stat().st_mode) & 0o022 == 0
