"""A component's fleet image as layers that follow what changes: the install tree read, the layers planned
(:mod:`robocore.plan.fleet_layers`), written and loaded (:mod:`robocore.adapters.image_layers`)."""

from __future__ import annotations

import os
from pathlib import Path, PurePosixPath
from typing import TYPE_CHECKING

from robocore.plan import naming
from robocore.plan.fleet_layers import COLCON_PACKAGES, InstallTree, Layer, component_layers
from robocore.plan.fleet_release import FleetImage

if TYPE_CHECKING:
    import docker

#: Largest colcon dependency record read (a line of package names).
MAX_RECORD = 100_000


def read_install_tree(root: Path, target: PurePosixPath) -> InstallTree:
    """The listing of the install tree at ``root``: each top folder with colcon's record of its package (isolated
    layout) is a package, with the dependencies the record names; everything else is one of ``others``."""
    packages: dict[str, tuple[str, ...]] = {}
    contents: dict[str, tuple[str, ...]] = {}
    others: list[str] = []
    for name in sorted(os.listdir(root)):
        record = root / name / COLCON_PACKAGES / name
        if (root / name).is_dir() and not (root / name).is_symlink() and record.is_file() \
                and not record.is_symlink():
            with record.open("rb") as handle:
                text = handle.read(MAX_RECORD).decode("utf-8", "replace")
            packages[name] = tuple(dep for dep in text.strip().split(":") if dep)
            contents[name] = tuple(sorted(os.listdir(root / name)))
        else:
            others.append(name)
    return InstallTree(root=root, target=target, packages=packages, others=tuple(others), contents=contents)


def image_layers(image: FleetImage) -> tuple[Layer, ...]:
    """The layers of ``image``'s fleet image, its install tree (if it carries one) read from disk."""
    install = next((f.source for f in image.layer if str(f.target) == naming.CONTAINER_INSTALL), None)
    tree = read_install_tree(install, PurePosixPath(naming.CONTAINER_INSTALL)) if install is not None else None
    return component_layers(image.layer, tree)


def build_layered(client: docker.DockerClient, image: FleetImage, parent: str) -> str:
    """``image`` made locally from ``parent`` (an image ID) and its layers, tagged ``image.ref``: its image ID."""
    from robocore.adapters.image_layers import load_layered

    return load_layered(client, parent, image_layers(image), image.labels, image.ref)


def layers_line(image: FleetImage) -> str:
    """``N layers (what each is)`` for the dry run of ``release --fleet``."""
    layers = image_layers(image)
    return f"{len(layers)} layer(s): " + "; ".join(layer.name for layer in layers)
