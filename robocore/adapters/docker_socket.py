"""Read-only Docker Engine API calls over the local unix socket, with the standard library only.

The no-op memo (:mod:`robocore.commands.support.noop`) must know whether the local images changed, and
``status`` what the local containers are doing, without paying for docker-py's import (requests,
urllib3: a large part of a no-op task's time). This adapter
answers only for a daemon on a unix socket (no ``DOCKER_HOST``, or ``unix://``); for any other
daemon, or any error, it answers None and the caller takes the ordinary path.
"""

from __future__ import annotations

import hashlib
import json
import os
import socket
from urllib.parse import quote

DEFAULT_SOCKET = "/var/run/docker.sock"
#: Seconds the one call may take before the caller takes the ordinary path.
TIMEOUT = 5.0


def socket_path(environ: dict[str, str] | None = None) -> str | None:
    """The local daemon's socket, or None when ``DOCKER_HOST`` (or a Docker context) names another kind."""
    env = os.environ if environ is None else environ
    if env.get("DOCKER_CONTEXT"):
        return None
    host = env.get("DOCKER_HOST", "")
    if not host:
        return DEFAULT_SOCKET
    return host[len("unix://"):] if host.startswith("unix://") else None


def get_json(path: str, *, environ: dict[str, str] | None = None) -> object | None:
    """``GET path`` on the local daemon, decoded; None when it cannot be asked or does not answer 200.

    A plain HTTP/1.0 exchange (the daemon answers with the whole body, then closes): http.client would
    cost more to import than the call takes."""
    where = socket_path(environ)
    if where is None:
        return None
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
            sock.settimeout(TIMEOUT)
            sock.connect(where)
            sock.sendall(f"GET {path} HTTP/1.0\r\nHost: docker\r\n\r\n".encode("ascii"))
            chunks = []
            while chunk := sock.recv(65536):
                chunks.append(chunk)
        head, _, body = b"".join(chunks).partition(b"\r\n\r\n")
        status = head.split(b"\r\n", 1)[0].split()
        if len(status) < 2 or status[1] != b"200" or b"transfer-encoding: chunked" in head.lower():
            return None
        found: object = json.loads(body)
        return found
    except (OSError, ValueError):
        return None


def images_digest(label: str, *, environ: dict[str, str] | None = None) -> str | None:
    """A digest of the local images carrying ``label`` (each image's ID and tags); None when it cannot be had.

    Any image built, retagged or removed with that label changes it."""
    filters = quote(json.dumps({"label": [label]}))
    found = get_json(f"/images/json?filters={filters}", environ=environ)
    if not isinstance(found, list):
        return None
    rows = sorted((str(image.get("Id")), sorted(image.get("RepoTags") or [])) for image in found
                  if isinstance(image, dict))
    return hashlib.sha256(json.dumps(rows).encode()).hexdigest()


def containers(label: str, *, environ: dict[str, str] | None = None) -> list[dict[str, object]] | None:
    """The inspect documents (as ``docker inspect`` gives them) of the local containers carrying ``label``,
    running or not; None when the daemon cannot be asked. One list call, then one inspect per container: what
    docker-py's ``containers.list(all=True)`` fetches, without its import. Any call that does not answer (a
    container removed between the two calls included) gives None: the caller asks through docker-py then."""
    filters = quote(json.dumps({"label": [label]}))
    listed = get_json(f"/containers/json?all=1&filters={filters}", environ=environ)
    if not isinstance(listed, list):
        return None
    found: list[dict[str, object]] = []
    for item in listed:
        ident = item.get("Id") if isinstance(item, dict) else None
        if not isinstance(ident, str):
            return None
        document = get_json(f"/containers/{quote(ident, safe='')}/json", environ=environ)
        if not isinstance(document, dict):
            return None
        found.append(document)
    return found
