"""A one-layer image archive in ``docker save`` form, streamed for ``docker load`` from a root file system tarball.

``docker import`` labels every image with the daemon's own arch (Docker 20.10 ignores the platform asked), and a
``FROM scratch`` + ``ADD`` build for another arch reads the tarball twice (into the build context, then into the
layer). An archive robocore writes itself names the arch in the image config and is read once: its one layer is
the tarball, whose diff ID is the tarball's sha256, so the daemon only unpacks and checks it.
"""

from __future__ import annotations

import hashlib
import json
import tarfile
import time
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path

from robocore.plan.arches import RootConfig

#: Bytes read at a time, while hashing the layer and while streaming it.
CHUNK = 1 << 20
_BLOCK = 512


def file_digest(path: Path) -> str:
    """``sha256:<hex>`` of a file's bytes (a layer's diff ID when the file is the uncompressed layer tar)."""
    digest = hashlib.sha256()
    with path.open("rb") as stream:
        while chunk := stream.read(CHUNK):
            digest.update(chunk)
    return "sha256:" + digest.hexdigest()


def image_config(*, arch: str, diff_id: str, labels: Mapping[str, str], cmd: Sequence[str],
                 created: str, comment: str, settings: RootConfig | None = None) -> bytes:
    """The image config JSON of a one-layer Linux image of ``arch`` (Docker's arch name, e.g. ``arm64``); with
    ``settings``, its environment, entrypoint, command and build shell (as a Dockerfile's ENV, ENTRYPOINT, CMD and
    SHELL would set them), else ``cmd`` alone."""
    run: dict[str, object] = {"Cmd": list(cmd), "Labels": dict(sorted(labels.items()))}
    if settings is not None:
        run.update(settings.image_config())
    config = {
        "architecture": arch,
        "os": "linux",
        "created": created,
        "config": run,
        "rootfs": {"type": "layers", "diff_ids": [diff_id]},
        "history": [{"created": created, "created_by": comment}],
    }
    return json.dumps(config, sort_keys=True, separators=(",", ":")).encode()


def _header(name: str, size: int, mtime: int) -> bytes:
    info = tarfile.TarInfo(name)
    info.size = size
    info.mode = 0o644
    info.mtime = mtime
    return info.tobuf(format=tarfile.USTAR_FORMAT)


def _padding(size: int) -> bytes:
    return b"\0" * (-size % _BLOCK)


class LoadArchive:
    """The archive of an image tagged ``reference`` (``name:tag``) whose one layer is the uncompressed tarball
    ``layer``, as a readable stream of known length (what ``docker load`` takes). The layer is hashed when the
    archive is made (one read) and streamed while it is read (a second read), never copied, so a scratch folder
    needs no room for a second tarball."""

    def __init__(self, layer: Path, *, reference: str, arch: str, labels: Mapping[str, str],
                 cmd: Sequence[str] = ("bash",), comment: str = "robocore: root file system",
                 settings: RootConfig | None = None) -> None:
        self.layer = layer
        self.diff_id = file_digest(layer)
        self.layer_size = layer.stat().st_size
        now = int(time.time())
        created = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(now))
        config = image_config(arch=arch, diff_id=self.diff_id, labels=labels, cmd=cmd, created=created,
                              comment=comment, settings=settings)
        config_name = hashlib.sha256(config).hexdigest() + ".json"
        self.layer_name = self.diff_id.removeprefix("sha256:") + "/layer.tar"
        manifest = json.dumps([{"Config": config_name, "RepoTags": [reference], "Layers": [self.layer_name]}])
        self.head = b"".join(_header(name, len(data), now) + data + _padding(len(data))
                             for name, data in (("manifest.json", manifest.encode()), (config_name, config)))
        self.head += _header(self.layer_name, self.layer_size, now)
        self.tail = _padding(self.layer_size) + b"\0" * (2 * _BLOCK)
        self._chunks = self._stream()
        self._current = b""
        self._offset = 0

    def __len__(self) -> int:
        return len(self.head) + self.layer_size + len(self.tail)

    def _stream(self) -> Iterator[bytes]:
        yield self.head
        sent = 0
        with self.layer.open("rb") as stream:
            while chunk := stream.read(CHUNK):
                sent += len(chunk)
                yield chunk
        if sent != self.layer_size:
            raise OSError(f"{self.layer} changed while it was being loaded ({sent} bytes, {self.layer_size} expected)")
        yield self.tail

    def read(self, size: int = -1) -> bytes:
        """Up to ``size`` bytes of the archive (all that is left when ``size`` is negative); b"" at its end.
        A read returns at most what is left of the current chunk, as a raw stream may."""
        if size < 0:
            rest = self._current[self._offset:] + b"".join(self._chunks)
            self._current, self._offset = b"", 0
            return rest
        while self._offset >= len(self._current):
            chunk = next(self._chunks, None)
            if chunk is None:
                return b""
            self._current, self._offset = chunk, 0
        out = self._current[self._offset:self._offset + size]
        self._offset += len(out)
        return out
