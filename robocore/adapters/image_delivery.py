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

import threading
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from robocore.errors import DockerError
from robocore.plan.registry_trust import push_hint
from robocore.ui import human_size

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
    image_id: str = ""  # the ID the host has the image under now ("" when not known here)

    def __str__(self) -> str:
        return f"{self.image}: {self.action}" + (f" ({human_size(self.bytes)})" if self.bytes else "")


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
                results[image] = Delivery(image, "present", image_id=str(local_image.id))
                continue
            same_id = _get(client, str(local_image.id))
            if same_id is not None:
                repo, tag = name.rsplit(":", 1)
                same_id.tag(repo, tag)
                results[image] = Delivery(image, "tagged", image_id=str(local_image.id))
                continue
            if registry:
                results[image] = _via_registry(local, client, local_image, name, registry)
            else:
                results[image] = _stream(local, client, local_image, name, progress=progress, label=label)
        except APIError as exc:
            raise DockerError(f"{label or 'host'}: delivering {name} failed: {exc.explanation or exc}",
                              hint="check free disk on the host (`robocore doctor`)") from None
    return results


def pull_for_arch(client: docker.DockerClient, refs: list[str], *, arch: str, label: str = "") -> dict[str, Delivery]:
    """Pull each of ``refs`` (a release's multi-arch names) on ``client``'s daemon for ``arch``, which the
    registry's manifest list resolves to that arch's image; a DockerError when it has none of that arch."""
    from docker.errors import APIError

    results: dict[str, Delivery] = {}
    for ref in refs:
        name = normalize(ref)
        repo, tag = name.rsplit(":", 1)
        try:
            check_stream(client.api.pull(repo, tag, stream=True, decode=True, platform=f"linux/{arch}"),
                         f"{label or 'host'}: pull {name} for linux/{arch}")
            found = str(client.images.get(name).attrs.get("Architecture") or "")
        except APIError as exc:
            raise DockerError(f"{label or 'host'}: pull of {name} for linux/{arch} failed: {exc.explanation or exc}",
                              hint="was it released (`robocore release --tag V`) with an image of that arch?") from None
        if found != arch:
            raise DockerError(f"{label or 'host'}: {name} resolved to an image of arch {found or 'unknown'}, "
                              f"not {arch}", hint="release again: every host's arch needs its image in the release")
        results[ref] = Delivery(name, "pulled")
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


#: Seconds between two lines of a push's progress (:func:`push_digest`): a long push is never silent.
PUSH_PROGRESS = 5.0


def push_digest(client: docker.DockerClient, target: str, tag: str,
                progress: Callable[[str], None] | None = None) -> str:
    """Push ``target:tag`` from this machine and return the digest the registry gave its manifest
    (``sha256:...``, from the push stream's last ``aux`` event); DockerError when the push fails or names none.
    ``progress`` is given a line every :data:`PUSH_PROGRESS` seconds while layers are sent: the megabytes sent of
    the layers being pushed (layers the registry has already are not sent)."""
    import time

    from docker.errors import APIError

    digest = ""
    sent: dict[str, tuple[int, int]] = {}  # layer id -> (bytes sent, its size)
    said = time.monotonic()
    try:
        for event in client.images.push(target, tag, stream=True, decode=True):
            if "error" in event:
                detail = event.get("errorDetail", {}).get("message") or event["error"]
                raise DockerError(f"push {target}:{tag} failed: {detail}", hint=push_hint(target, str(detail)))
            detail = event.get("progressDetail") or {}
            if event.get("status") == "Pushing" and isinstance(detail.get("current"), int):
                sent[str(event.get("id"))] = (detail["current"], int(detail.get("total") or detail["current"]))
            if progress is not None and sent and time.monotonic() - said >= PUSH_PROGRESS:
                done, total = sum(d for d, _ in sent.values()), sum(t for _, t in sent.values())
                progress(f"pushing {target}:{tag}: {done / 1e6:.1f} of {total / 1e6:.1f} MB sent")
                said = time.monotonic()
            aux = event.get("aux")
            if isinstance(aux, dict) and isinstance(aux.get("Digest"), str):
                digest = aux["Digest"]
    except APIError as exc:
        detail = str(exc.explanation or exc)
        raise DockerError(f"push {target}:{tag} failed: {detail}", hint=push_hint(target, detail)) from None
    if not digest.startswith("sha256:"):
        raise DockerError(f"push {target}:{tag}: the registry named no digest for it")
    return digest


def _stream(local: docker.DockerClient, remote: docker.DockerClient, image: Any, name: str, *,
            progress: bool, label: str) -> Delivery:
    have = _remote_chains(remote)
    skip = _present_layers(image.attrs.get("RootFS", {}).get("Layers", []), have)
    total = int(image.attrs.get("Size", 0))
    counter = _Counter()
    raw = image.save(chunk_size=1 << 20, named=name)
    body = counter.wrap(without_layers(raw, skip) if skip else raw)
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


class _Reader:
    """Exact-size reads from an iterator of byte chunks."""

    def __init__(self, chunks: Iterable[bytes]) -> None:
        self._it = iter(chunks)
        self._buf = bytearray()

    def read(self, n: int) -> bytes:
        while len(self._buf) < n:
            try:
                self._buf += next(self._it)
            except StopIteration:
                break
        out = bytes(self._buf[:n])
        del self._buf[:n]
        return out

    def rest(self) -> Iterator[bytes]:
        if self._buf:
            yield bytes(self._buf)
            self._buf.clear()
        yield from self._it


_BLOCK = 512
_SPOOL_IN_MEMORY = 1 << 20


def _tar_size(header: bytes) -> int:
    field = header[124:136]
    if field[0] & 0x80:  # base-256 (GNU) for sizes >= 8 GiB
        return int.from_bytes(field[1:], "big")
    text = field.split(b"\0", 1)[0].strip() or b"0"
    return int(text, 8)


def _member(reader: _Reader, count: int) -> Iterator[bytes]:
    """The next ``count`` bytes of a tar stream (a member and its padding), in chunks of at most 1 MiB;
    fewer when the stream ends early."""
    remaining = count
    while remaining:
        block = reader.read(min(remaining, 1 << 20))
        if not block:
            return
        remaining -= len(block)
        yield block


def without_layers(chunks: Iterable[bytes], skip: set[str]) -> Iterator[bytes]:
    """Re-stream a ``docker save`` tar, leaving out the layer tars whose diff ID is in ``skip``.

    A layer's diff ID is the sha256 of its uncompressed tar, so every regular member is hashed
    (spooled to a temp file when large) and dropped when its digest is a layer the host has;
    everything else is passed through byte for byte. Memory stays bounded.
    """
    import hashlib
    import tempfile

    reader = _Reader(chunks)
    pending: list[bytes] = []  # pax/GNU long-name headers that belong to the next member
    while True:
        header = reader.read(_BLOCK)
        if len(header) < _BLOCK or header == bytes(_BLOCK):
            yield from pending
            yield header
            yield from reader.rest()
            return
        size = _tar_size(header)
        padded = -(-size // _BLOCK) * _BLOCK
        kind = header[156:157]
        if kind in (b"x", b"g", b"L", b"K"):
            pending.append(header + reader.read(padded))
            continue
        if kind not in (b"0", b"\0") or size == 0:
            yield from pending
            pending.clear()
            yield header
            yield from _member(reader, padded)
            continue
        digest = hashlib.sha256()
        with tempfile.SpooledTemporaryFile(max_size=_SPOOL_IN_MEMORY) as spool:
            left_in_file = size
            for block in _member(reader, padded):
                digest.update(block[:left_in_file])
                left_in_file = max(0, left_in_file - len(block))
                spool.write(block)
            if f"sha256:{digest.hexdigest()}" in skip:
                pending.clear()
                continue
            yield from pending
            pending.clear()
            yield header
            spool.seek(0)
            while block := spool.read(1 << 20):
                yield block
