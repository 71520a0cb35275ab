"""Content hashes of what an image or a colcon build is made from (never timestamps).

An image is rebuilt when, and only when, the hash of its inputs differs from the
``dev.robocore.inputs`` label of the existing image. The inputs are the Dockerfile text,
every file of the build context (path, executable bit, content digest), the image it
starts from (by ID) and the target platform.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

#: Bump to invalidate every image robocore built before a change of the hashing itself.
HASH_VERSION = "1"


@dataclass(frozen=True, order=True)
class FileDigest:
    """One file of a build context: its path in the context, executable bit and content digest."""

    path: str
    executable: bool
    sha256: str


def digest_bytes(data: bytes) -> str:
    """The sha256 hex digest of ``data``."""
    return hashlib.sha256(data).hexdigest()


def inputs_hash(
    dockerfile: str,
    files: Iterable[FileDigest],
    *,
    parent: str,
    platform: str,
    extra: Mapping[str, str] | None = None,
) -> str:
    """The content hash of an image's inputs.

    ``parent`` identifies the image it starts from (an image ID, or a name when the ID is not
    known yet); ``extra`` holds anything else that changes the result (sorted by key).
    """
    document = {
        "version": HASH_VERSION,
        "dockerfile": dockerfile,
        "files": [[f.path, f.executable, f.sha256] for f in sorted(files)],
        "parent": parent,
        "platform": platform,
        "extra": dict(sorted((extra or {}).items())),
    }
    text = json.dumps(document, sort_keys=True, separators=(",", ":"))
    return "sha256:" + hashlib.sha256(text.encode("utf-8")).hexdigest()


def tree_hash(files: Iterable[FileDigest]) -> str:
    """A hash of a set of files (a package's source tree, for incremental colcon builds)."""
    text = json.dumps([[f.path, f.executable, f.sha256] for f in sorted(files)], separators=(",", ":"))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()
