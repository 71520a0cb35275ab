"""The Docker CLI's ``docker manifest`` (manifest lists: one name, one image per arch), the one thing of
Docker that robocore runs as a command: docker-py has no manifest-list API.

It also reads an image's manifest (``docker manifest inspect``): the sizes of its layers, from which ``fleet
rollout`` says what each robot will pull (:mod:`robocore.plan.pull_bytes`).

The CLI is chosen over speaking the registry's HTTP API here because it reads the user's registry
credentials (``docker login``, credential helpers) and trust settings (``certs.d``) as ``docker push`` does;
robocore would otherwise have to re-implement the registry's token authentication.
"""

from __future__ import annotations

import json
import shlex
import shutil
import subprocess
from collections.abc import Sequence

from robocore.errors import DockerError, ToolMissing
from robocore.plan.pull_bytes import ImageLayers, parse_manifest


def docker_cli() -> str:
    """The docker command-line client's path, or ToolMissing."""
    found = shutil.which("docker")
    if found is None:
        raise ToolMissing("the docker command-line client is not installed (release makes multi-arch names with "
                          "`docker manifest`)", hint="install it (Debian: apt-get install docker.io, or docker-ce-cli)")
    return found


def run(argv: Sequence[str], *, what: str, timeout: float = 600) -> str:
    """Run a ``docker manifest`` argv; its stdout, or a DockerError with its last error line."""
    try:
        proc = subprocess.run(list(argv), capture_output=True, text=True, timeout=timeout, check=False)
    except subprocess.TimeoutExpired:
        raise DockerError(f"{what}: no answer within {timeout:.0f} s", hint="is the registry reachable?") from None
    if proc.returncode != 0:
        lines = [line for line in proc.stderr.strip().splitlines() if line.strip()]
        raise DockerError(f"{what} failed: {lines[-1] if lines else f'exit {proc.returncode}'}",
                          hint=f"the command was: {shlex.join(argv)}")
    return proc.stdout


def image_layers(ref: str, *, insecure: bool, timeout: float = 60) -> ImageLayers:
    """The layers and configuration of the image ``ref`` (by digest: a single-arch image) as its registry's
    manifest gives them; ``insecure``: the registry speaks plain HTTP. A DockerError naming ``ref`` otherwise."""
    argv = [docker_cli(), "manifest", "inspect", *(["--insecure"] if insecure else []), "--", ref]
    text = run(argv, what=f"reading the manifest of {ref}", timeout=timeout)
    try:
        return parse_manifest(json.loads(text))
    except ValueError as exc:  # not JSON, or a manifest list
        raise DockerError(f"the manifest of {ref} is not an image's: {exc}") from None
