"""Docker image builds and build containers through docker-py (the local daemon).

Build contexts are made in memory from :class:`~robocore.plan.dockerfiles.ContextEntry` items;
folders are copied recursively without VCS metadata and Python caches.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import stat
import tarfile
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from robocore.errors import BuildError, DockerError, UnsafePath
from robocore.plan.dockerfiles import ContextEntry, ImagePlan, rosdep_unresolved
from robocore.plan.inputs import FileDigest, digest_bytes

if TYPE_CHECKING:
    import docker

SKIP_DIRS = frozenset({".git", ".hg", ".svn", "__pycache__", ".mypy_cache", ".pytest_cache", ".ruff_cache"})
SKIP_SUFFIXES = (".pyc", ".pyo")
PROXY_VARS = ("http_proxy", "https_proxy", "no_proxy", "HTTP_PROXY", "HTTPS_PROXY", "NO_PROXY")

Output = Callable[[str], None]


@dataclass(frozen=True)
class ContextFile:
    """One regular file or symlink of a build context, resolved on the dev machine."""

    dest: str
    data: bytes
    executable: bool = False
    link: str | None = None  # symlink target (data is empty)

    def digest(self) -> FileDigest:
        """Its content digest."""
        content = b"link:" + self.link.encode() if self.link is not None else self.data
        return FileDigest(self.dest, self.executable, digest_bytes(content))


def walk(root: Path) -> Iterator[tuple[str, Path]]:
    """Files and symlinks under ``root`` as (relative posix path, path), sorted, caches and VCS skipped."""
    for dirpath, dirnames, filenames in os.walk(root):
        links = [d for d in dirnames if os.path.islink(os.path.join(dirpath, d))]
        dirnames[:] = sorted(d for d in dirnames if d not in SKIP_DIRS and d not in links)
        for name in sorted(filenames + links):
            if name.endswith(SKIP_SUFFIXES):
                continue
            path = Path(dirpath) / name
            yield path.relative_to(root).as_posix(), path


def _file(dest: str, path: Path) -> ContextFile:
    info = path.lstat()
    if stat.S_ISLNK(info.st_mode):
        return ContextFile(dest, b"", link=os.readlink(path))
    if not stat.S_ISREG(info.st_mode):  # a FIFO would block the read for ever, a device never end
        raise UnsafePath(f"{path}: is not a regular file (a FIFO, socket or device); robocore copies only files "
                         "and links into images", hint=f"remove {path}")
    return ContextFile(dest, path.read_bytes(), executable=bool(info.st_mode & 0o111))


def expand(entries: Iterable[ContextEntry]) -> list[ContextFile]:
    """Resolve context entries (literal data, host files, host folders) into files."""
    files: list[ContextFile] = []
    for entry in entries:
        if entry.data is not None:
            files.append(ContextFile(entry.dest, entry.data, entry.executable))
        elif entry.source is not None and entry.source.is_dir() and not entry.source.is_symlink():
            files += [_file(f"{entry.dest}/{rel}", path) for rel, path in walk(entry.source)]
        elif entry.source is not None:
            files.append(_file(entry.dest, entry.source))
    return files


def make_tar(dockerfile: str, files: Sequence[ContextFile]) -> io.BytesIO:
    """An in-memory tar build context with ``Dockerfile`` and ``files`` (fixed mtimes, root-owned)."""
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w") as tar:
        seen_dirs: set[str] = set()

        def add_dirs(path: str) -> None:
            parts = path.split("/")[:-1]
            for i in range(1, len(parts) + 1):
                folder = "/".join(parts[:i])
                if folder not in seen_dirs:
                    seen_dirs.add(folder)
                    info = tarfile.TarInfo(folder)
                    info.type = tarfile.DIRTYPE
                    info.mode = 0o755
                    tar.addfile(info)

        data = dockerfile.encode("utf-8")
        info = tarfile.TarInfo("Dockerfile")
        info.size = len(data)
        info.mode = 0o644
        tar.addfile(info, io.BytesIO(data))
        for item in files:
            add_dirs(item.dest)
            info = tarfile.TarInfo(item.dest)
            if item.link is not None:
                info.type = tarfile.SYMTYPE
                info.linkname = item.link
                info.mode = 0o777
                tar.addfile(info)
                continue
            info.size = len(item.data)
            info.mode = 0o755 if item.executable else 0o644
            tar.addfile(info, io.BytesIO(item.data))
    buffer.seek(0)
    return buffer


@dataclass(frozen=True)
class ImageState:
    """An image present on the daemon."""

    id: str
    labels: Mapping[str, str]
    size: int
    arch: str


def image_state(client: docker.DockerClient, ref: str) -> ImageState | None:
    """The image ``ref`` if present locally, else None."""
    from docker.errors import ImageNotFound

    try:
        image = client.images.get(ref)
    except ImageNotFound:
        return None
    attrs: dict[str, Any] = image.attrs
    labels = (attrs.get("Config") or {}).get("Labels") or {}
    return ImageState(id=str(image.id), labels=dict(labels), size=int(attrs.get("Size", 0)),
                      arch=str(attrs.get("Architecture", "")))


def proxy_buildargs() -> dict[str, str]:
    """Proxy variables of the dev machine, passed as Docker's predefined build args."""
    return {name: os.environ[name] for name in PROXY_VARS if os.environ.get(name)}


def build_image(
    client: docker.DockerClient,
    plan: ImagePlan,
    files: Sequence[ContextFile],
    *,
    labels: Mapping[str, str],
    native_arch: str,
    output: Output | None = None,
    nocache: bool = False,
) -> str:
    """Build ``plan`` and tag it; return the image ID, or raise BuildError with the last output lines."""
    from docker.errors import APIError, DockerException

    # One LABEL instruction at the end (docker-py's labels= adds one build step per label).
    dockerfile = plan.dockerfile
    if labels:
        dockerfile += "LABEL " + " ".join(f"{key}={json.dumps(value)}" for key, value in sorted(labels.items())) + "\n"
    context = make_tar(dockerfile, files)
    kwargs: dict[str, Any] = {}
    if plan.arch != native_arch:
        kwargs["platform"] = plan.platform
    tail: list[str] = []
    image_id: str | None = None
    try:
        stream = client.api.build(
            fileobj=context, custom_context=True, tag=plan.ref, rm=True, forcerm=True, nocache=nocache,
            pull=False, decode=True, buildargs=proxy_buildargs(), **kwargs,
        )
        for chunk in stream:
            if "error" in chunk:
                detail = str(chunk.get("error", "")).strip()
                unresolved = rosdep_unresolved(tail)
                if unresolved:  # one line: the keys, not the build's tail
                    raise BuildError(f"image {plan.ref}: rosdep cannot install the dependencies: "
                                     + "; ".join(unresolved),
                                     hint="correct the key in the package.xml, or name the Debian/Ubuntu package in "
                                          "the component's apt_packages instead")
                raise BuildError(
                    f"image {plan.ref}: build failed: {detail}\n" + "\n".join(tail[-25:]),
                    hint="the lines above are the end of the build output",
                )
            text = chunk.get("stream")
            if isinstance(text, str):
                for line in text.splitlines():
                    if line.strip():
                        tail.append(line.rstrip())
                        if output is not None:
                            output(line.rstrip())
                del tail[:-50]
            aux = chunk.get("aux")
            if isinstance(aux, dict) and "ID" in aux:
                image_id = str(aux["ID"])
    except (APIError, DockerException) as exc:
        raise DockerError(f"image {plan.ref}: the Docker daemon refused the build: {exc}") from None
    if image_id is None:
        state = image_state(client, plan.ref)
        if state is None:
            raise BuildError(f"image {plan.ref}: the build ended without an image")
        image_id = state.id
    return image_id


def run_streaming(
    client: docker.DockerClient,
    image: str,
    command: Sequence[str],
    *,
    user: str,
    volumes: Mapping[str, str],
    environment: Mapping[str, str],
    labels: Mapping[str, str],
    name: str | None = None,
    platform: str | None = None,
    on_line: Output | None = None,
) -> int:
    """Run ``command`` in a throw-away container, stream its output lines, return its exit code."""
    from docker.errors import DockerException

    binds = {host: {"bind": inside, "mode": "rw"} for host, inside in volumes.items()}
    try:
        container = client.containers.create(
            image, list(command), user=user, volumes=binds, environment=dict(environment), labels=dict(labels),
            working_dir="/robocore/build", name=name, network_mode="host", platform=platform, detach=True,
        )
    except DockerException as exc:
        raise DockerError(f"cannot create a build container from {image}: {exc}") from None
    try:
        container.start()
        buffer = b""
        for chunk in container.logs(stream=True, follow=True):
            buffer += chunk
            *lines, rest = buffer.split(b"\n")
            buffer = rest
            for line in lines:
                if on_line is not None:
                    on_line(line.decode("utf-8", "replace"))
        if buffer and on_line is not None:
            on_line(buffer.decode("utf-8", "replace"))
        result = container.wait()
        return int(result.get("StatusCode", 1))
    finally:
        with contextlib.suppress(DockerException):
            container.remove(force=True)
