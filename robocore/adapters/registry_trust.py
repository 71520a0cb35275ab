"""A fleet registry's CA on a robot host, through the robot's own Docker daemon (no ssh, no shell on the robot).

``fleet join`` puts the CA where the robot's dockerd reads it at each pull, ``/etc/docker/certs.d/<registry>/
ca.crt`` (no restart): a container that never runs, made from a tiny local image with no program in it
(:data:`HELPER_IMAGE`, imported on the robot from a few bytes, nothing pulled), with the host's certs.d folder
bind-mounted; the file goes in through Docker's archive API and the container is removed. Docker mounts a
container's volumes for the archive API, running or not. Works on any daemon robocore may use (its user can run
containers, so it may write there), and on a robot of any arch.
"""

from __future__ import annotations

import contextlib
import io
import tarfile
import time
from typing import TYPE_CHECKING

from robocore.errors import DockerError
from robocore.plan.registry_trust import CERTS_D, ca_archive, ca_file, file_in_archive

if TYPE_CHECKING:
    import docker

#: The helper image: one empty folder, no program (its containers are never started).
HELPER_IMAGE = "robocore-certs-helper:1"
#: Where the host's certs.d folder is mounted in the helper container.
MOUNTED = "/certs.d"
#: Label of the helper's containers (so that a left-over one is recognisable).
HELPER_LABEL = "dev.robocore.helper"


def _helper_tar() -> bytes:
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w") as tar:
        folder = tarfile.TarInfo("certs.d")
        folder.type, folder.mode = tarfile.DIRTYPE, 0o755
        tar.addfile(folder)
    return buffer.getvalue()


def _ensure_helper(client: docker.DockerClient) -> None:
    from docker.errors import ImageNotFound

    try:
        client.images.get(HELPER_IMAGE)
    except ImageNotFound:
        repo, tag = HELPER_IMAGE.rsplit(":", 1)
        client.api.import_image_from_data(_helper_tar(), repository=repo, tag=tag)


def install_ca(client: docker.DockerClient, registry: str, pem: bytes) -> str:
    """Make ``pem`` the CA of ``registry`` on the daemon of ``client``'s host: ``installed``, or ``unchanged`` when
    that file already holds it. DockerError naming what failed."""
    from docker.errors import APIError, NotFound

    container = ""
    try:
        _ensure_helper(client)
        made = client.api.create_container(
            HELPER_IMAGE, command=["/robocore-never-started"], labels={HELPER_LABEL: "registry-ca"},
            host_config=client.api.create_host_config(binds={CERTS_D: {"bind": MOUNTED, "mode": "rw"}}))
        container = str(made["Id"])
        try:
            stream, _ = client.api.get_archive(container, f"{MOUNTED}/{ca_file(registry)}")
            if file_in_archive(b"".join(stream)) == pem:
                return "unchanged"
        except NotFound:
            pass
        if not client.api.put_archive(container, MOUNTED, ca_archive(registry, pem, int(time.time()))):
            raise DockerError(f"writing {CERTS_D}/{ca_file(registry)} was refused by the daemon")
        return "installed"
    except APIError as exc:
        raise DockerError(f"installing the registry's CA at {CERTS_D}/{ca_file(registry)}: "
                          f"{exc.explanation or exc}") from None
    finally:
        if container:
            with contextlib.suppress(APIError):
                client.api.remove_container(container, force=True)
