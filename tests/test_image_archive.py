"""The ``docker load`` archive a root file system tarball becomes: its form, its config's arch, its one layer."""

from __future__ import annotations

import hashlib
import io
import json
import tarfile
from pathlib import Path

import pytest

from robocore.adapters.image_archive import CHUNK, LoadArchive


def _layer(tmp_path: Path, size: int) -> Path:
    root = tmp_path / "root"
    (root / "etc").mkdir(parents=True)
    (root / "etc" / "blob").write_bytes(bytes(range(256)) * (size // 256) + b"x" * (size % 256))
    tarball = tmp_path / "root.tar"
    with tarfile.open(tarball, "w") as archive:
        archive.add(root, arcname=".")
    return tarball


def _read_all(archive: LoadArchive, size: int) -> bytes:
    parts = []
    while chunk := archive.read(size):
        assert len(chunk) <= size
        parts.append(chunk)
    return b"".join(parts)


def _members(data: bytes) -> dict[str, bytes]:
    with tarfile.open(fileobj=io.BytesIO(data), mode="r:") as archive:
        out = {}
        for member in archive.getmembers():
            extracted = archive.extractfile(member)
            assert extracted is not None
            out[member.name] = extracted.read()
        return out


@pytest.mark.parametrize("read_size", [1 << 13, 7, CHUNK + 3, -1])
def test_archive_is_a_docker_save_tar_whose_layer_is_the_tarball(tmp_path: Path, read_size: int) -> None:
    layer = _layer(tmp_path, 3 * CHUNK + 123)  # several chunks and a partial last block
    archive = LoadArchive(layer, reference="robocore/arm64/debian:bookworm-debian", arch="arm64",
                          labels={"b": "2", "a": "1"}, comment="made here")
    data = archive.read(-1) if read_size < 0 else _read_all(archive, read_size)
    assert len(data) == len(archive)
    assert len(data) % 512 == 0

    members = _members(data)
    manifest = json.loads(members["manifest.json"])
    assert len(manifest) == 1
    entry = manifest[0]
    assert entry["RepoTags"] == ["robocore/arm64/debian:bookworm-debian"]
    digest = hashlib.sha256(layer.read_bytes()).hexdigest()
    assert entry["Layers"] == [f"{digest}/layer.tar"]
    assert members[entry["Layers"][0]] == layer.read_bytes()
    config_bytes = members[entry["Config"]]
    assert entry["Config"] == hashlib.sha256(config_bytes).hexdigest() + ".json"  # the image ID names it
    config = json.loads(config_bytes)
    assert config["architecture"] == "arm64"
    assert config["os"] == "linux"
    assert config["rootfs"] == {"type": "layers", "diff_ids": [f"sha256:{digest}"]}
    assert config["config"] == {"Cmd": ["bash"], "Labels": {"a": "1", "b": "2"}}
    assert config["history"][0]["created_by"] == "made here"


def test_archive_refuses_a_tarball_that_changed_after_hashing(tmp_path: Path) -> None:
    layer = _layer(tmp_path, 2 * CHUNK)
    archive = LoadArchive(layer, reference="r:t", arch="amd64", labels={})
    with layer.open("ab") as grow:
        grow.write(b"\0" * 512)  # its diff ID no longer matches what the daemon would read
    with pytest.raises(OSError, match="changed while it was being loaded"):
        _read_all(archive, CHUNK)


def test_archive_length_is_known_before_reading(tmp_path: Path) -> None:
    layer = _layer(tmp_path, 1000)
    archive = LoadArchive(layer, reference="r:t", arch="amd64", labels={})
    expected = len(archive)  # requests sends it as Content-Length
    assert len(archive.read(-1)) == expected
    assert archive.read(512) == b""
