"""Getting images onto a robot host's Docker daemon, with or without a registry.

- With a registry: the image is tagged ``<registry>/<name>`` and pushed once per process from
  this machine, then pulled on the host and tagged back to ``<name>`` so that containers and
  compose files use one name everywhere.
- Without one (robots in the field are often offline): ``docker save`` on this machine is
  streamed straight into ``docker load`` on the host over its Docker connection (ssh, tls, ...),
  no temp file. Images the host already has (same image ID) are skipped; an image whose ID the
  host has under another name is only tagged. Layers the host already has are left out of the
  stream (``docker load`` only reads a layer it does not have), so re-delivering a component
  image after a change moves its new layers only. A rich progress bar counts bytes.
"""

from __future__ import annotations

import io
import tarfile
import threading
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from robocore.errors import DockerError

if TYPE_CHECKING:
    import docker

_pushed: set[tuple[str, str]] = set()
_push_lock = threading.Lock()


@dataclass(frozen=True)
class Delivery:
    """What happened to one image on one host."""

    image: str
    action: str  # present | tagged | loaded | pulled
    bytes: int = 0

    def __str__(self) -> str:
        return f"{self.image}: {self.action}" + (f" ({_human(self.bytes)})" if self.bytes else "")


def normalize(image: str) -> str:
    """``name`` -> ``name:latest``; names that carry a tag or digest are unchanged."""
    last = image.rsplit("/", 1)[-1]
    return image if (":" in last or "@" in image) else f"{image}:latest"


def ensure_images(client: docker.DockerClient, images: list[str], *, registry: str | None,
                  progress: bool = True, source: docker.DockerClient | None = None,
                  label: str = "") -> dict[str, Delivery]:
    """Make every image of ``images`` (local names) present on ``client``'s daemon, same image IDs.

    ``source`` is this machine's daemon (default: the local one). ``label`` names the host in
    progress output. Returns one :class:`Delivery` per image. Raises DockerError.
    """
    from docker.errors import APIError, ImageNotFound

    from robocore.adapters.docker_hosts import local_client

    local = source or local_client(timeout=600)
    results: dict[str, Delivery] = {}
    for image in images:
        name = normalize(image)
        try:
            local_image = local.images.get(name)
        except ImageNotFound:
            raise DockerError(f"image {name} is not on this machine",
                              hint="run `stage` (and `prepare-base`) first") from None
        try:
            remote_image = _get(client, name)
            if remote_image is not None and remote_image.id == local_image.id:
                results[image] = Delivery(image, "present")
                continue
            same_id = _get(client, str(local_image.id))
            if same_id is not None:
                repo, tag = name.rsplit(":", 1)
                same_id.tag(repo, tag)
                results[image] = Delivery(image, "tagged")
                continue
            if registry:
                results[image] = _via_registry(local, client, local_image, name, registry)
            else:
                results[image] = _stream(local, client, local_image, name, progress=progress, label=label)
        except APIError as exc:
            raise DockerError(f"{label or 'host'}: delivering {name} failed: {exc.explanation or exc}",
                              hint="check free disk on the host (`robocore doctor`)") from None
    return results


def _get(client: docker.DockerClient, ref: str) -> Any:
    from docker.errors import ImageNotFound

    try:
        return client.images.get(ref)
    except ImageNotFound:
        return None


def _via_registry(local: docker.DockerClient, remote: docker.DockerClient, image: Any, name: str,
                  registry: str) -> Delivery:
    repo, tag = name.rsplit(":", 1)
    prefix = registry.rstrip("/") + "/"
    target = repo if repo.startswith(prefix) else prefix + repo
    with _push_lock:
        if (image.id, f"{target}:{tag}") not in _pushed:
            image.tag(target, tag)
            check_stream(local.images.push(target, tag, stream=True, decode=True), f"push {target}:{tag}")
            _pushed.add((image.id, f"{target}:{tag}"))
    check_stream(remote.api.pull(target, tag, stream=True, decode=True), f"pull {target}:{tag}")
    pulled = remote.images.get(f"{target}:{tag}")
    pulled.tag(repo, tag)
    if pulled.id != image.id:
        raise DockerError(f"pulled {target}:{tag} has ID {str(pulled.id)[:19]}, this machine has {image.id[:19]}",
                          hint="another push replaced the tag; re-run")
    return Delivery(name, "pulled")


def check_stream(events: Iterable[dict[str, Any]], what: str) -> None:
    """Raise DockerError on the first error event of a push, pull or load stream."""
    for event in events:
        if "error" in event:
            detail = event.get("errorDetail", {}).get("message") or event["error"]
            raise DockerError(f"{what} failed: {detail}",
                              hint="is the registry reachable from this machine and from the host?")


def _stream(local: docker.DockerClient, remote: docker.DockerClient, image: Any, name: str, *,
            progress: bool, label: str) -> Delivery:
    have = _remote_chains(remote)
    skip = _present_layers(image.attrs.get("RootFS", {}).get("Layers", []), have)
    total = int(image.attrs.get("Size", 0))
    counter = _Counter()
    raw = image.save(chunk_size=1 << 20, named=name)
    body = counter.wrap(_without_layers(raw, skip) if skip else raw)
    if not progress:
        _load(remote, body, name)
        return Delivery(name, "loaded", counter.sent)

    from rich.progress import BarColumn, DownloadColumn, Progress, TextColumn, TransferSpeedColumn

    from robocore.ui import console

    with Progress(TextColumn("{task.description}"), BarColumn(), DownloadColumn(), TransferSpeedColumn(),
                  console=console(), transient=False) as bar:
        task = bar.add_task(f"{label + ': ' if label else ''}{name}", total=total or None)
        counter.on_chunk = lambda n: bar.advance(task, n)
        _load(remote, body, name)
        bar.update(task, total=counter.sent, completed=counter.sent)
    return Delivery(name, "loaded", counter.sent)


def _load(remote: docker.DockerClient, body: Iterator[bytes], name: str) -> None:
    api: Any = remote.api
    events = api.load_image(body)
    check_stream(events or [], f"load {name}")


class _Counter:
    def __init__(self) -> None:
        self.sent = 0
        self.on_chunk: Callable[[int], None] | None = None

    def wrap(self, chunks: Iterable[bytes]) -> Iterator[bytes]:
        for chunk in chunks:
            self.sent += len(chunk)
            if self.on_chunk is not None:
                self.on_chunk(len(chunk))
            yield chunk


def _remote_chains(remote: docker.DockerClient) -> set[tuple[str, ...]]:
    """Every layer-chain prefix of every image on the host."""
    chains: set[tuple[str, ...]] = set()
    for img in remote.images.list(all=True):
        layers = img.attrs.get("RootFS", {}).get("Layers", [])
        for i in range(1, len(layers) + 1):
            chains.add(tuple(layers[:i]))
    return chains


def _present_layers(layers: list[str], chains: set[tuple[str, ...]]) -> set[str]:
    """Diff IDs of the longest prefix of ``layers`` that the host already has as a chain."""
    k = 0
    while k < len(layers) and tuple(layers[: k + 1]) in chains:
        k += 1
    return set(layers[:k])


class _Pipe(io.RawIOBase):
    """A file-like view of an iterator of byte chunks (for tarfile's stream mode)."""

    def __init__(self, chunks: Iterable[bytes]) -> None:
        self._it = iter(chunks)
        self._buf = b""

    def readable(self) -> bool:
        return True

    def readinto(self, b: Any) -> int:
        while not self._buf:
            try:
                self._buf = next(self._it)
            except StopIteration:
                return 0
        n = min(len(b), len(self._buf))
        b[:n] = self._buf[:n]
        self._buf = self._buf[n:]
        return n


class _Sink(io.RawIOBase):
    def __init__(self) -> None:
        self.out: list[bytes] = []

    def writable(self) -> bool:
        return True

    def write(self, b: Any) -> int:
        self.out.append(bytes(b))
        return len(b)

    def take(self) -> bytes:
        data = b"".join(self.out)
        self.out.clear()
        return data


def _without_layers(chunks: Iterable[bytes], skip: set[str]) -> Iterator[bytes]:
    """Re-stream a ``docker save`` tar, dropping ``layer.tar`` members whose diff ID is in ``skip``.

    A layer's diff ID is the sha256 of its uncompressed tar, so each layer is hashed while it is
    spooled to a temp file; members the host needs are written through unchanged.
    """
    import hashlib
    import tempfile

    sink = _Sink()
    source = tarfile.open(fileobj=io.BufferedReader(_Pipe(chunks), 1 << 20), mode="r|")  # noqa: SIM115
    target = tarfile.open(fileobj=sink, mode="w|", format=tarfile.PAX_FORMAT)  # noqa: SIM115
    for member in source:
        data = source.extractfile(member) if member.isfile() else None
        if data is None:
            target.addfile(member)
        elif member.name.endswith("layer.tar"):
            digest = hashlib.sha256()
            with tempfile.TemporaryFile() as spool:
                while block := data.read(1 << 20):
                    digest.update(block)
                    spool.write(block)
                if f"sha256:{digest.hexdigest()}" not in skip:
                    spool.seek(0)
                    target.addfile(member, spool)
        else:
            target.addfile(member, io.BytesIO(data.read()))
        if chunk := sink.take():
            yield chunk
    target.close()
    source.close()
    if chunk := sink.take():
        yield chunk


def _human(n: int) -> str:
    size = float(n)
    for unit in ("B", "KB", "MB", "GB"):
        if size < 1024 or unit == "GB":
            return f"{size:.0f} {unit}" if unit == "B" else f"{size:.1f} {unit}"
        size /= 1024
    return f"{n} B"
