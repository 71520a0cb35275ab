"""The bytes a robot pulls to run a release, from the registry's manifests (pure).

A robot's Docker Engine keeps layers **by chain** (a layer and every layer below it): pulling an image, it skips
a layer only while every layer up to it is one it holds in the same order, and downloads every layer from the
first it lacks, even one whose bytes it holds under another chain (moby's ``distribution/xfer``). So the bytes
of a target image on a robot are the compressed sizes of its layers from the first whose chain none of the
robot's images has, plus its configuration blob; layers the robot's other new images also pull are counted
once, as the engine downloads them once.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass


@dataclass(frozen=True)
class ImageLayers:
    """An image as its registry manifest describes it: its configuration blob and layers (digest, bytes)."""

    config: tuple[str, int]
    layers: tuple[tuple[str, int], ...]

    @property
    def size(self) -> int:
        """Every byte of it: a robot that holds nothing of it pulls that much."""
        return self.config[1] + sum(size for _, size in self.layers)


def parse_manifest(data: Mapping[str, object]) -> ImageLayers:
    """An image manifest (Docker schema 2 or OCI) as :class:`ImageLayers`; ValueError for anything else (a
    manifest list, which names no layers)."""
    config, layers = data.get("config"), data.get("layers")
    if not isinstance(config, Mapping) or not isinstance(layers, list):
        raise ValueError("not an image manifest (no config and layers; a manifest list?)")

    def blob(item: object) -> tuple[str, int]:
        if not isinstance(item, Mapping) or not isinstance(item.get("digest"), str) \
                or not isinstance(item.get("size"), int):
            raise ValueError("a blob without digest or size")
        return str(item["digest"]), int(item["size"])

    return ImageLayers(config=blob(config), layers=tuple(blob(layer) for layer in layers))


def _chains(image: ImageLayers) -> list[tuple[str, ...]]:
    digests = [digest for digest, _ in image.layers]
    return [tuple(digests[:end]) for end in range(1, len(digests) + 1)]


def pull_bytes(targets: Iterable[ImageLayers], held: Iterable[ImageLayers]) -> int:
    """Bytes a robot that holds the images ``held`` downloads to hold every image of ``targets`` as well
    (see the module); 0 when it holds them all."""
    have = {chain for image in held for chain in _chains(image)}
    configs = {image.config[0] for image in held}
    fetched: set[tuple[str, ...]] = set()
    total = 0
    for image in targets:
        if image.config[0] not in configs:
            configs.add(image.config[0])
            total += image.config[1]
        for chain, (_, size) in zip(_chains(image), image.layers, strict=True):
            if chain not in have and chain not in fetched:
                fetched.add(chain)
                total += size
    return total


@dataclass(frozen=True)
class RobotBytes:
    """What one robot pulls for a rollout: bytes of what it lacks, beside the whole of the target's images."""

    robot: str
    pull: int
    whole: int
    known: bool  # False when what the robot runs is unknown (nothing of this project, or an image not found)


def robot_bytes(robot: str, targets: Sequence[ImageLayers], held: Sequence[ImageLayers] | None) -> RobotBytes:
    """:func:`pull_bytes` of one robot; ``held`` None when what it runs is unknown: the whole is counted."""
    whole = pull_bytes(targets, [])
    if held is None:
        return RobotBytes(robot, whole, whole, known=False)
    return RobotBytes(robot, pull_bytes(targets, held), whole, known=True)


def human(size: int) -> str:
    """``size`` bytes for a person: B, kB, MB, GB (powers of 1000, as registries and Docker show them)."""
    value = float(size)
    for unit in ("B", "kB", "MB"):
        if value < 1000:
            return f"{value:.0f} {unit}" if unit == "B" else f"{value:.1f} {unit}"
        value /= 1000
    return f"{value:.2f} GB"
