"""Local stand-ins for the official ROS images, named as the real ones (``ros:jazzy-ros-base``,
``ros:noetic-ros-base``).

robocore's default base (``base: official``) starts ``FROM ros:<distro>-ros-base``. No registry can be reached on
these machines, so the suites build images of that name here from what can be reached, keeping what robocore relies
on: ``/ros_entrypoint.sh``, ``/opt/ros/<distro>/setup.bash``, apt (Debian's mirror plus a local "ROS apt
repository"), rosdep with an offline database (a sources list and a rosdistro index served from files) and, for
ROS 2, colcon. ``tree/install.sh`` makes it in one container of a Debian root, committed once with the image settings
of ``standin.changes`` (one layer: a Dockerfile would commit one per step, seconds each on this storage driver).

- ROS 2 (jazzy): the wheels base's Debian root (``robocore/amd64/debian:bookworm-wheels``) plus the ROS 2 wheels
  robocore pins for its wheels base, installed as a ROS prefix under ``/opt/ros/jazzy`` for the system python3;
- ROS 1 (noetic): the debian base's Debian root (``robocore/<arch>/debian:bookworm-debian``, which holds Debian 12's
  ROS 1 packages) plus rosdep; for arm64 the root the arm64 suites bootstrap (:mod:`arm64_project`).

Each image carries :data:`LABEL`, the hash of its inputs (these files, the root's ID, the wheels), and a name of its
own (:data:`OWN_REPOSITORY`; the label alone cannot find it: every image built on it inherits the label); it is built
only when the image of that name lacks the hash. :func:`ensure` then points the upstream name at it, as
``docker pull --platform`` would; robocore's ``prepare-base`` resolves it from there (:mod:`robocore.adapters.rootfs`).
Docker holds one arch of a name at a time: making the arm64 noetic stand-in moves ``ros:noetic-ros-base`` to it, as a
pull of that platform would, and the amd64 one stays where robocore pinned it (``robocore/amd64/ros:noetic-ros-base``).
"""

from __future__ import annotations

import hashlib
import io
import json
import shlex
import tarfile
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from robocore import resources
from robocore.adapters import rootfs
from robocore.adapters.image_builder import image_state, proxy_buildargs
from robocore.commands.support.machine import find_ca_bundle
from robocore.config.model import BaseKind
from robocore.plan import arches, dockerfiles, naming

HERE = Path(__file__).parent
#: The image settings the stand-in is committed with (``ENV``, ``ENTRYPOINT``, ``CMD``: as ``docker commit --change``).
CHANGES = HERE / "standin.changes"
TREE = HERE / "tree"
#: The hash of a stand-in's inputs.
LABEL = "dev.robocore.it.standin"
#: Where each stand-in keeps a name of its own.
OWN_REPOSITORY = "robocore-it/ros-standin"
#: ROS 1 distros (the others are ROS 2).
ROS1 = frozenset({"noetic"})
#: Beside robocore's pinned ROS 2 wheels: psutil (``fastdds discovery`` needs it) and empy 3, as the real images
#: have it (Debian's colcon, like the ROS apt repository's, needs empy 3's API; the wheels would bring empy 4, whose
#: ``em`` module would shadow it: colcon then loads none of its build tasks and builds nothing).
WHEELS_EXTRA = ("psutil", "empy<4")
#: Where a missing Debian root is bootstrapped (robocore's own bootstrap, as its prepare-base would).
WORK = Path(tempfile.gettempdir()) / "robocore-it-standins"


@dataclass(frozen=True)
class Standin:
    """The stand-in for ``ros:<distro>-ros-base`` of one arch."""

    distro: str
    arch: str

    @property
    def generation(self) -> int:
        """1 or 2."""
        return 1 if self.distro in ROS1 else 2

    @property
    def reference(self) -> str:
        """The real image's name, which the stand-in takes."""
        return f"ros:{self.distro}-ros-base"

    @property
    def kind(self) -> BaseKind:
        """The registry-free base whose Debian root the stand-in starts from."""
        return BaseKind.debian if self.generation == 1 else BaseKind.wheels

    @property
    def root(self) -> str:
        """That root (``robocore/<arch>/debian:bookworm-<kind>``)."""
        return arches.root_image(self.kind, self.arch)

    @property
    def own_name(self) -> str:
        """The stand-in's own name, which nothing else moves (``robocore-it/ros-standin:<distro>-<arch>``)."""
        return f"{OWN_REPOSITORY}:{self.distro}-{self.arch}"

    @property
    def pinned(self) -> str:
        """The per-arch name robocore gives the official root once it has it (``robocore/<arch>/ros:...``)."""
        return arches.pinned_image(self.reference, self.arch)

    def settings(self) -> str:
        """``tree/standin.env``, read by ``tree/install.sh``: the distro, its generation and (ROS 2) the wheels."""
        wheels = " ".join(dockerfiles.WHEELS[self.distro] + WHEELS_EXTRA) if self.generation == 2 else ""
        installer = dockerfiles.WHEELS_INSTALLER if self.generation == 2 else ""
        values = {"DISTRO": self.distro, "GENERATION": str(self.generation), "WHEELS": wheels, "INSTALLER": installer}
        return "".join(f"{key}={shlex.quote(value)}\n" for key, value in values.items())


def _files(standin: Standin) -> dict[str, bytes]:
    """The stand-in's inputs, without the CA bundle and the proxy settings: its image settings, the tree, the tree's
    settings and (ROS 2) robocore's small ``ros2`` command (the wheels have no ros2cli; the real images have it)."""
    files = {"changes": CHANGES.read_bytes().replace(b"@DISTRO@", standin.distro.encode())}
    files.update({f"tree/{path.name}": path.read_bytes() for path in sorted(TREE.iterdir()) if path.is_file()})
    files["tree/standin.env"] = standin.settings().encode()
    if standin.generation == 2:
        files["tree/ros2"] = resources.read("ros2")
    return files


def inputs_hash(standin: Standin, root_id: str) -> str:
    """The hash :data:`LABEL` holds: the context's files (settings included), the root's ID and the arch."""
    digest = hashlib.sha256()
    for name, data in sorted(_files(standin).items()):
        digest.update(name.encode() + b"\0" + hashlib.sha256(data).digest())
    digest.update(json.dumps([root_id, standin.arch]).encode())
    return "sha256:" + digest.hexdigest()


def _changes(standin: Standin, labels: dict[str, str]) -> list[str]:
    """The ``docker commit --change`` lines: :data:`CHANGES`, then one LABEL of the inputs and of robocore's labels the
    root carries, emptied (a root robocore bootstrapped is labelled as such; the stand-in is not one, as a pulled
    image is not)."""
    text = _files(standin)["changes"].decode()
    lines = [line for line in text.splitlines() if line.strip() and not line.startswith("#")]
    return [*lines, "LABEL " + " ".join(f"{key}={json.dumps(value)}" for key, value in sorted(labels.items()))]


def _tree(standin: Standin) -> io.BytesIO:
    """The tree as a tar archive to unpack at ``/``: ``tmp/standin/...``, with the dev machine's CA bundle and its
    proxy settings (``proxy.env``; as environment of the container they would stay in the committed image)."""
    files = {name: data for name, data in _files(standin).items() if name.startswith("tree/")}
    ca = find_ca_bundle()
    files["tree/host-ca.pem"] = ca.read_bytes() if ca is not None else b""
    files["tree/proxy.env"] = "".join(f"{key}={shlex.quote(value)}\n"
                                      for key, value in sorted(proxy_buildargs().items())).encode()
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w") as tar:
        for name, data in sorted(files.items()):
            info = tarfile.TarInfo("tmp/standin/" + name.removeprefix("tree/"))
            info.size = len(data)
            info.mode = 0o755 if name.endswith((".sh", "/ros2", ".py")) else 0o644
            tar.addfile(info, io.BytesIO(data))
    buffer.seek(0)
    return buffer


def _build(client: Any, standin: Standin, root: str, digest: str, say: Callable[[str], None]) -> str:
    """``tree/install.sh`` run in a container of the root, then the container committed with :func:`_changes`: the
    stand-in's image ID. Not a Dockerfile build: that commits each of its steps (six), this one layer."""
    labels = {LABEL: digest, naming.LABEL_ROLE: "", naming.LABEL_INPUTS: ""}
    what = f"stand-in {standin.reference} ({standin.arch})"
    container = client.containers.create(root, ["/tmp/standin/install.sh"], entrypoint=["/bin/bash"], user="root",
                                         working_dir="/", platform=arches.platform(standin.arch))
    try:
        container.put_archive("/", _tree(standin))
        container.start()
        tail: list[str] = []
        pending = b""
        for chunk in container.logs(stream=True, follow=True):
            *lines, pending = (pending + chunk).split(b"\n")
            for line in lines:
                text = line.decode(errors="replace").rstrip()
                if text:
                    tail = [*tail, text][-30:]
                    say(text)
        code = container.wait()["StatusCode"]
        if code != 0:
            raise RuntimeError(f"{what}: tree/install.sh exited {code}\n" + "\n".join(tail))
        image = container.commit(changes=_changes(standin, labels))
        if image.attrs.get("Architecture") != standin.arch:  # a commit keeps its root's arch; checked, not assumed
            raise RuntimeError(f"{what}: committed as {image.attrs.get('Architecture')}")
        return str(image.id)
    finally:
        container.remove(force=True)


def ensure(client: Any, standin: Standin, say: Callable[[str], None] = lambda _: None, *, pin: bool = False) -> str:
    """The stand-in's image ID, built when its own name does not hold its inputs hash, and named
    :attr:`Standin.reference`, as ``docker pull --platform linux/<arch>`` of the real image would leave it. A missing
    root is made by robocore's own bootstrap.

    ``pin``: name it :attr:`Standin.pinned` instead (the name robocore's ``prepare-base`` gives the root once it has
    resolved it) and leave :attr:`Standin.reference` alone: Docker holds one arch of that name at a time, and a suite
    may be using its other arch meanwhile (the arm64 images made in the background, :mod:`arm64_project`)."""
    from robocore.commands.prepare_base import ROOTFS_KINDS

    assert standin.kind in ROOTFS_KINDS
    packages = dockerfiles.DEBIAN_APT if standin.kind is BaseKind.debian else dockerfiles.WHEELS_APT
    strap = arches.root_strap(standin.kind, standin.arch, packages)
    root, root_id = rootfs.ensure_root_image(client, target=standin.root, upstream=f"debian:{arches.SUITE}",
                                             arch=standin.arch, strap=strap, work_dir=WORK, status=say)
    digest = inputs_hash(standin, root_id)
    # found by a name of its own: the label alone would not do, every image built on the stand-in inherits it
    made = image_state(client, standin.own_name)
    if made is not None and made.arch == standin.arch and made.labels.get(LABEL) == digest:
        image_id = made.id
    else:
        image_id = _build(client, standin, root, digest, say)
        repository, tag = arches.split_reference(standin.own_name)
        client.api.tag(image_id, repository, tag=tag, force=True)
    repository, tag = arches.split_reference(standin.pinned if pin else standin.reference)
    client.api.tag(image_id, repository, tag=tag, force=True)
    return image_id


def forget_pinned(client: Any, standin: Standin) -> None:
    """Remove robocore's per-arch name of the official root (``robocore/<arch>/ros:<distro>-ros-base``), so that
    the next ``prepare-base`` resolves the root from the upstream name, as on a machine that just pulled it."""
    state = image_state(client, standin.pinned)
    if state is not None:
        client.images.remove(standin.pinned, noprune=True)


#: The folder (and so image prefix) of ``test_official_arm64``'s project; :mod:`arm64_project` makes its images ahead
#: of time in a copy of the same name.
ARM64_PROJECT = "robocore-it-official-arm64"
#: Its arm64 host's address: prepare-base, stage and build contact no host (TEST-NET-1).
ARM64_HOST = "192.0.2.211"


def arm64_project(root: Path, *, domain: int, port: int) -> None:
    """Make the noetic project ``robocore init --defaults`` wrote at ``root`` the arm64 project of
    ``test_official_arm64``: one arm64 host running every component and the ROS master (on ``port``), ROS domain
    ``domain``. Neither number is an input of its images, so a copy made with other numbers has the same ones."""
    robot_yaml = root / "robot.yaml"
    data = yaml.safe_load(robot_yaml.read_text())
    data["ros_domain_id"] = domain
    data["hosts"] = [{"name": "robot-arm", "ip": ARM64_HOST, "user": "root", "arch": "arm64"}]
    data["discovery"] = {"servers": [{"host": "robot-arm", "port": port}]}
    for comp in data["components"]:
        comp["runs_on"] = "robot-arm"
    robot_yaml.write_text(yaml.safe_dump(data, sort_keys=False))
