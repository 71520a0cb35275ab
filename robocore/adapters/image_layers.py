"""A fleet image made of layers robocore writes itself, loaded into the local Docker daemon (docker-py).

``docker build`` cannot give one layer per ROS package that stays the same between releases: a layer it makes
holds the folders it touched with the time of the build, so the same files give another layer digest in every
build without the cache, and every layer above a changed one is made again. Here each layer
(:class:`~robocore.plan.fleet_layers.Layer`) is a tar written by robocore, the same bytes for the same files:

- entries in name order, each folder before what it holds, the folders above each file included;
- owner and group root (0, no names), time 0, modes 0755 (folders, executables), 0644 (files), links as they are;
- Python caches and VCS folders left out (:func:`robocore.adapters.image_builder.walk`), as the builds do.

The image is loaded (``docker load``) from an archive that holds the image's configuration
(:func:`~robocore.plan.fleet_layers.layered_config`) and the new layers only: the daemon reads a layer file only
for a layer it does not hold, and the parent's are held. The daemon keeps each layer's tar as written, so the
pushed layer has the same digest as the tar robocore wrote (its ``diff_id``).
"""

from __future__ import annotations

import hashlib
import io
import json
import tarfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from robocore.adapters.image_builder import ContextFile, expand
from robocore.errors import DockerError
from robocore.plan.dockerfiles import ContextEntry
from robocore.plan.fleet_layers import Layer, layered_config

if TYPE_CHECKING:
    import docker


@dataclass(frozen=True)
class LayerTar:
    """A layer's tar, its ``diff_id`` (sha256 of the tar) and what it is."""

    name: str
    data: bytes

    @property
    def diff_id(self) -> str:
        """``sha256:<hex>`` of the uncompressed tar: the layer's identity in the image's configuration."""
        return "sha256:" + hashlib.sha256(self.data).hexdigest()


def _info(name: str, kind: bytes, mode: int) -> tarfile.TarInfo:
    info = tarfile.TarInfo(name)
    info.type, info.mode, info.mtime, info.uid, info.gid, info.uname, info.gname = kind, mode, 0, 0, 0, "", ""
    return info


def layer_tar(layer: Layer) -> LayerTar:
    """The tar of ``layer`` (see the module): the same files give the same bytes."""
    files: list[ContextFile] = expand(ContextEntry(dest=str(item.target).lstrip("/"), source=item.source)
                                      for item in layer.files)
    folders: set[str] = set()
    for item in files:
        parts = item.dest.split("/")[:-1]
        folders.update("/".join(parts[:end]) for end in range(1, len(parts) + 1))
    entries: dict[str, ContextFile | None] = {folder: None for folder in folders}
    entries.update({item.dest: item for item in files})
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w", format=tarfile.PAX_FORMAT) as tar:
        for name in sorted(entries, key=lambda n: n.split("/")):
            found = entries[name]
            if found is None:
                tar.addfile(_info(name, tarfile.DIRTYPE, 0o755))
            elif found.link is not None:
                info = _info(name, tarfile.SYMTYPE, 0o777)
                info.linkname = found.link
                tar.addfile(info)
            else:
                info = _info(name, tarfile.REGTYPE, 0o755 if found.executable else 0o644)
                info.size = len(found.data)
                tar.addfile(info, io.BytesIO(found.data))
    return LayerTar(layer.name, buffer.getvalue())


def load_layered(client: docker.DockerClient, parent: str, layers: Sequence[Layer], labels: Mapping[str, str],
                 ref: str) -> str:
    """Load into the daemon the image ``parent`` (an image ID) plus ``layers``, with ``labels``, tagged ``ref``
    (``repo:tag``); its image ID (the sha256 of its configuration, the same for the same parent and files)."""
    from docker.errors import APIError, DockerException

    tars = [layer_tar(layer) for layer in layers]
    try:
        attrs: dict[str, Any] = client.api.inspect_image(parent)  # type: ignore[no-untyped-call]
        history: list[dict[str, Any]] = client.api.history(parent)  # type: ignore[no-untyped-call]
    except DockerException as exc:
        raise DockerError(f"image {parent}: cannot be read for its fleet image: {exc}") from None
    config = json.dumps(layered_config(attrs, history, [t.diff_id for t in tars], [t.name for t in tars], labels),
                        sort_keys=True, separators=(",", ":")).encode()
    image_id = "sha256:" + hashlib.sha256(config).hexdigest()
    parent_count = len((attrs.get("RootFS") or {}).get("Layers") or [])
    # the parent's layers are named, not carried: the daemon holds them, and reads a layer's file only when not
    paths = [f"parent/{index}.tar" for index in range(parent_count)] + [f"{t.diff_id[7:]}/layer.tar" for t in tars]
    manifest = [{"Config": f"{image_id[7:]}.json", "RepoTags": [ref], "Layers": paths}]
    archive = io.BytesIO()
    with tarfile.open(fileobj=archive, mode="w") as tar:
        members = [(f"{image_id[7:]}.json", config), ("manifest.json", json.dumps(manifest).encode())]
        members += [(f"{t.diff_id[7:]}/layer.tar", t.data) for t in tars]
        for name, data in members:
            info = _info(name, tarfile.REGTYPE, 0o644)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    try:
        client.images.load(archive.getvalue())
    except (APIError, DockerException) as exc:
        raise DockerError(f"image {ref}: the Docker daemon refused its layers: {exc}") from None
    return image_id
