"""Per-arch names and facts of everything robocore makes for a CPU arch (pure).

An arch is a value carried with every image, tree and cache key, decided here once:

- the **root image** a base is built FROM is always a per-arch local name, ``robocore/<arch>/...``, so two
  arches never share a name even when they come from one multi-arch reference: the wheels and debian
  bases' Debian root is ``robocore/<arch>/debian:bookworm-<kind>``, the wheels base's
  ``...:bookworm-wheels-<distro>`` (bootstrapped with ``mmdebstrap --arch``, the wheels one with the base's venv
  and settings, or ``debian:bookworm`` pulled with its platform and tagged so), an official base's
  ``ros:<distro>-ros-base`` (or ``base.image``) is pulled with its platform and tagged
  ``robocore/<arch>/<reference>``;
- the **base image** is ``<prefix>base:latest`` on the dev machine's arch and ``<prefix>base:latest-<arch>``
  for another; every image's inputs hash includes its platform, a root's includes its arch;
- **ccache** is ``.robocore/ccache/<arch>``;
- an **install tree** records the arch it was built for in ``install/`` :data:`INSTALL_ARCH_FILE`, and
  ``sync`` compares it (and the ELF headers of its files) with the host's arch.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

from robocore.config.model import BaseKind, Robot

#: The Debian release of the registry-free roots.
SUITE = "bookworm"
#: Repository of the per-arch local names (``robocore/<arch>/...``).
LOCAL_PREFIX = "robocore"
#: File in an install tree naming the arch its binaries were built for (one line: ``arm64``).
INSTALL_ARCH_FILE = ".robocore-arch"
#: ELF ``e_machine`` values of the arches robocore knows.
ELF_MACHINES = {62: "amd64", 183: "arm64"}
#: Folder of the per-arch ccache caches, under the project's ``.robocore/``.
CCACHE_FOLDER = "ccache"

_UNSAFE = re.compile(r"[^a-z0-9._/-]+")


def platform(arch: str) -> str:
    """Docker platform string of an arch (``linux/arm64``)."""
    return f"linux/{arch}"


def base_tag(arch: str, native: str) -> str:
    """Tag of the base image for ``arch``: ``latest`` on the dev machine's arch, else ``latest-<arch>``."""
    return "latest" if arch == native else f"latest-{arch}"


def root_image(kind: BaseKind, arch: str, distro: str = "") -> str:
    """The Debian root image of a wheels or debian base for ``arch``: ``robocore/<arch>/debian:bookworm-<kind>``;
    with ``distro`` (the wheels base: its root holds that distro's venv) ``...:bookworm-<kind>-<distro>``."""
    return f"{LOCAL_PREFIX}/{arch}/debian:{SUITE}-{kind.value}" + (f"-{distro}" if distro else "")


def split_reference(ref: str) -> tuple[str, str]:
    """``(repository, tag)`` of an image reference; ``latest`` when it has none, the digest for ``repo@sha256:``."""
    if "@" in ref:
        repository, _, digest = ref.partition("@")
        return repository, digest.replace(":", "-")[:40]
    last = ref.rsplit("/", 1)[-1]
    if ":" in last:
        repository, _, tag = ref.rpartition(":")
        return repository, tag
    return ref, "latest"


def pinned_image(ref: str, arch: str) -> str:
    """The per-arch local name of a pulled image: ``ros:noetic-ros-base`` -> ``robocore/arm64/ros:noetic-ros-base``.

    A multi-arch reference holds one arch at a time on a daemon (pulling another platform moves the tag);
    the per-arch name keeps each arch's image where the base's FROM finds it.
    """
    repository, tag = split_reference(ref)
    safe = _UNSAFE.sub("-", repository.lower().replace(":", "-")).strip("/-") or "image"
    return f"{LOCAL_PREFIX}/{arch}/{safe}:{tag}"


def base_root(robot: Robot, arch: str) -> str:
    """What the base image for ``arch`` is built FROM (always a per-arch local name)."""
    if robot.base.kind is BaseKind.official:
        return pinned_image(upstream_root(robot), arch)
    if robot.base.image:
        return pinned_image(robot.base.image, arch)
    if robot.base.kind is BaseKind.wheels:  # the root robocore bootstraps holds the distro's venv
        return root_image(robot.base.kind, arch, robot.ros_distro.value)
    return root_image(robot.base.kind, arch)


def upstream_root(robot: Robot) -> str:
    """The reference a base's root comes from when it is pulled (``ros:<distro>-ros-base``, ``debian:bookworm``
    or ``base.image``)."""
    if robot.base.image:
        return robot.base.image
    if robot.base.kind is BaseKind.official:
        return f"ros:{robot.ros_distro.value}-ros-base"
    return f"debian:{SUITE}"


#: Where Debian's python3 packages' modules are byte-compiled from (``py3compile``'s default folder and the
#: private ones of the roots' packages: debpython's and catkin's).
PYTHON_MODULE_DIRS = ("/usr/lib/python3/dist-packages", "/usr/share/python3", "/usr/share/catkin")
#: Byte-compiling once, at the end: each of Debian's python3 packages runs ``py3compile`` when it is set up,
#: a Python start per package, which is slow under qemu (docs/design-notes.md, "arm64 under emulation"). Once
#: the essential packages are in, the real ``py3compile`` is diverted away (python3-minimal then unpacks it as
#: ``py3compile.later``) and a no-op stands in its place (python3's runtime hooks call it unconditionally); at
#: the end the no-op goes, the real one is put back, and one ``compileall`` run compiles the same folders.
#: mmdebstrap runs each hook with the root folder as ``$1``; no value of robot.yaml is in them.
COMPILE_LATER_HOOKS = (
    '--essential-hook=chroot "$1" dpkg-divert --quiet --local --rename --divert /usr/bin/py3compile.later '
    "--add /usr/bin/py3compile && printf '#!/bin/sh\\nexit 0\\n' > \"$1/usr/bin/py3compile\" "
    '&& chmod 755 "$1/usr/bin/py3compile"',
    '--customize-hook=rm -f "$1/usr/bin/py3compile" '
    '&& chroot "$1" dpkg-divert --quiet --local --rename --remove /usr/bin/py3compile',
    '--customize-hook=chroot "$1" sh -c \'[ ! -x /usr/bin/python3 ] || for d in '
    + " ".join(PYTHON_MODULE_DIRS)
    + '; do [ ! -d "$d" ] || python3 -m compileall -q "$d" || exit 1; done\'',
)


#: Docker's PATH for a container whose image sets none (what a Dockerfile's ``$PATH`` is on a root that sets none).
DEFAULT_PATH = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"


@dataclass(frozen=True)
class RootConfig:
    """Settings a bootstrapped root's image config carries, as ENV, ENTRYPOINT, CMD and SHELL steps would set them:
    the wheels base's own, given to its root so that its Dockerfile needs none of those steps (on fuse-overlayfs
    each step of a build costs a walk of the whole image, seconds on a root that holds the venv)."""

    env: tuple[tuple[str, str], ...] = ()
    entrypoint: tuple[str, ...] = ()
    cmd: tuple[str, ...] = ("bash",)
    shell: tuple[str, ...] = ()

    def image_config(self) -> dict[str, list[str]]:
        """The image config's ``Env``, ``Entrypoint``, ``Cmd`` and ``Shell`` (those set)."""
        config = {"Env": [f"{name}={value}" for name, value in self.env], "Entrypoint": list(self.entrypoint),
                  "Cmd": list(self.cmd), "Shell": list(self.shell)}
        return {key: value for key, value in config.items() if value}

    def key(self) -> list[str]:
        """The lines of a root's content hash that name these settings."""
        return [f"{name}={value}" for name, value in self.env] + ["--", *self.entrypoint, "--", *self.cmd, "--",
                                                                  *self.shell]


@dataclass(frozen=True)
class RootStrap:
    """How a registry-free root is bootstrapped for one arch (the mmdebstrap inputs of its content hash)."""

    arch: str
    packages: tuple[str, ...]
    variant: str = "apt"
    excludes: tuple[str, ...] = ("/usr/share/doc/*", "/usr/share/man/*", "/usr/share/locale/*")
    hooks: tuple[str, ...] = COMPILE_LATER_HOOKS
    #: the venv the last of ``hooks`` installs into the root ("": none), see :mod:`robocore.plan.wheels_venv`
    venv: str = ""
    #: the image config's settings (None: ``Cmd`` bash alone)
    config: RootConfig | None = None

    def argv(self, tarball: str, mirror: str) -> list[str]:
        """The mmdebstrap command line writing the root to ``tarball`` from ``mirror`` (the caller checks that
        the mirror is a URL and the tarball an absolute path, so neither is read as an option)."""
        argv = ["mmdebstrap", f"--arch={self.arch}", f"--variant={self.variant}",
                f"--include={','.join(self.packages)}", '--aptopt=APT::Install-Recommends "false"']
        argv += [f"--dpkgopt=path-exclude={pattern}" for pattern in self.excludes]
        return [*argv, *self.hooks, SUITE, tarball, mirror]

    def key(self) -> str:
        """The text its content hash is made from (arch, variant, packages, excludes, hooks, venv)."""
        extra = ["--", self.venv] if self.venv else []  # a root without them keeps the hash it had
        extra += ["--", *self.config.key()] if self.config is not None else []
        return "\n".join([SUITE, self.arch, self.variant, *self.packages, "--", *self.excludes, "--", *self.hooks,
                          *extra])


def root_strap(kind: BaseKind, arch: str, packages: Sequence[str], *, venv: str = "",
               venv_hook: str = "", config: RootConfig | None = None) -> RootStrap:
    """The bootstrap of ``kind``'s root for ``arch``: the base's own apt packages are unpacked by mmdebstrap
    (natively, with only maintainer scripts emulated), so the base's apt step has nothing left to do. With
    ``venv`` and its ``venv_hook`` (the wheels base, :func:`robocore.plan.wheels_venv.root_hook`), the hook runs
    last, once the root's Python modules are compiled, and the root holds the base's venv too; ``config``: the
    settings of its image config."""
    del kind  # the packages are the kind's; the name carries the kind
    if bool(venv) != bool(venv_hook):
        raise ValueError("a root's venv and the hook that installs it come together")
    hooks = COMPILE_LATER_HOOKS + ((venv_hook,) if venv_hook else ())
    return RootStrap(arch=arch, packages=tuple(sorted(set(packages))), hooks=hooks, venv=venv, config=config)


def elf_arch(header: bytes) -> str | None:
    """The arch of an ELF file from its first 20 bytes (``arm64``, ``amd64``, ``machine-<n>``); None if not ELF."""
    if len(header) < 20 or header[:4] != b"\x7fELF":
        return None
    machine = int.from_bytes(header[18:20], "little" if header[5] == 1 else "big")
    return ELF_MACHINES.get(machine, f"machine-{machine}")
