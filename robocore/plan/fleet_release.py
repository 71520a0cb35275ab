"""Self-contained release images for a fleet, and the release record that names them by digest (pure).

A single robot gets its code by ``sync`` (install trees beside code-less images). A fleet engine runs
images only, so ``release --fleet --tag V`` pushes, per component (and its host's arch), the
component's staged image plus **one** layer holding what ``sync`` would ship for it:

- its colcon install tree, at ``/robocore/install`` (where ``run`` mounts the synced tree), and
- its read-only project volumes (``./config:/params:ro``), at their container paths, so a fleet
  service mounts nothing from the project.

The DDS profiles and compose files that ``sync`` also ships are not in the image: they depend on each
robot's addresses and are made per robot by the fleet engine. The base image of every arch in use is
pushed too, as it is: discovery servers run it.

Each image is pushed as ``<registry>/<repo>:V-<arch>-fleet`` and recorded by digest in the release
record ``.robocore/releases/V.json`` (:class:`ReleaseRecord`, private to the user), so that a robot
runs exactly the bytes that were tested: ``component -> arch -> <registry>/<repo>@sha256:...``.
The fleet engines read it with :func:`parse_release_record` (through
:func:`robocore.commands.fleet_release.load_release_record`) and ask
:meth:`ReleaseRecord.component_ref` / :meth:`ReleaseRecord.base_ref`.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

from robocore.config.model import Component, read_only_project_path
from robocore.config.values import IMAGE_REF
from robocore.errors import UsageError
from robocore.plan import naming
from robocore.plan.dockerfiles import ContextEntry

#: Suffix of a fleet image's tag (``V-<arch>-fleet``): the code-less release of the same version is ``V-<arch>``.
FLEET_TAG_SUFFIX = "fleet"
#: The build context folder that holds the layer's files, copied to ``/`` by the layer's one instruction.
LAYER_ROOT = "rootfs"
#: Version of the release record's format.
RECORD_FORMAT = 1
#: Labels the layer carries (what it is a release of).
LABEL_VERSION = "dev.robocore.release"
LABEL_COMPONENT = "dev.robocore.component"

_SHA256 = re.compile(r"@sha256:[0-9a-f]{64}")


@dataclass(frozen=True)
class LayerFile:
    """One local file or folder the layer carries, and where it is in the image."""

    source: Path
    target: PurePosixPath


@dataclass(frozen=True)
class FleetImage:
    """One image a fleet release pushes: a local image, plus a layer when ``layer`` is not empty."""

    component: str  # the component's name; "" for the base image
    arch: str
    source: str  # the local image it starts from (repository:tag)
    target: str  # <registry>/<repo>
    tag: str  # V-<arch>-fleet
    layer: tuple[LayerFile, ...] = ()
    labels: Mapping[str, str] = field(default_factory=dict)

    @property
    def ref(self) -> str:
        """``target:tag``."""
        return f"{self.target}:{self.tag}"

    @property
    def is_base(self) -> bool:
        """True for the base image (discovery servers run it)."""
        return self.component == ""


@dataclass(frozen=True)
class FleetReleasePlan:
    """Every image of a fleet release, bases first."""

    version: str
    registry: str
    images: tuple[FleetImage, ...]


def fleet_tag(version: str, arch: str) -> str:
    """``V-<arch>-fleet``, or a UsageError when that is not a valid image tag (a version too long)."""
    tag = f"{version}-{arch}-{FLEET_TAG_SUFFIX}"
    if not naming.is_image_tag(tag):
        raise UsageError(f"{version!r} is not a version a fleet release can take: {tag!r} is not a valid image tag",
                         hint="a version of at most 110 letters, digits, '_', '.', '-', starting with a letter or "
                              "digit")
    return tag


def layer_files(component: Component, install: Path | None, project_root: Path) -> tuple[LayerFile, ...]:
    """What the layer of ``component`` carries: its install tree (``install``, None without a workspace) at
    ``/robocore/install``, then each read-only project volume at its container path (sources resolved in
    ``project_root``; the command checks beforehand that they stay in the project)."""
    files: list[LayerFile] = []
    if install is not None:
        files.append(LayerFile(install, PurePosixPath(naming.CONTAINER_INSTALL)))
    for volume in component.volumes:
        rel = read_only_project_path(volume)
        if rel is not None:
            files.append(LayerFile(project_root / rel, PurePosixPath(volume.split(":")[1])))
    return tuple(files)


def baked_volumes(component: Component) -> tuple[str, ...]:
    """The volumes of ``component`` its fleet image carries (read-only project volumes): a fleet engine mounts
    the others and not these."""
    return tuple(v for v in component.volumes if read_only_project_path(v) is not None)


def layer_dockerfile(parent: str, labels: Mapping[str, str]) -> str:
    """The Dockerfile of a component's layer: its image (``parent``, by image ID), one ``COPY`` of the layer's
    files (so exactly one layer is added) and labels (configuration only, no layer)."""
    lines = [f"FROM {parent}", f"COPY {LAYER_ROOT}/ /"]
    if labels:
        lines.append("LABEL " + " ".join(f"{key}={json.dumps(value)}" for key, value in sorted(labels.items())))
    return "\n".join(lines) + "\n"


def layer_context(files: Sequence[LayerFile]) -> tuple[ContextEntry, ...]:
    """The build context entries of a layer: each file or folder under :data:`LAYER_ROOT` at its image path."""
    return tuple(ContextEntry(dest=f"{LAYER_ROOT}{file.target}", source=file.source) for file in files)


@dataclass(frozen=True)
class FleetSource:
    """A local image a fleet release starts from: a component's (with its layer's files) or the base of an arch."""

    component: str  # "" for the base image
    arch: str
    source: str  # the local image (repository:tag)
    repo: str  # its repository under the registry (the local name: <image_prefix><component>, <image_prefix>base)
    layer: tuple[LayerFile, ...] = ()


def plan_fleet_release(registry: str, version: str, sources: Sequence[FleetSource]) -> FleetReleasePlan:
    """The images of a fleet release of ``version`` to ``registry``, in the order of ``sources``; a source with
    layer files gets one layer and labels naming the release and the component."""
    prefix = registry.rstrip("/")
    images = []
    for item in sources:
        labels = {LABEL_VERSION: version, LABEL_COMPONENT: item.component} if item.layer else {}
        images.append(FleetImage(item.component, item.arch, item.source, f"{prefix}/{item.repo}",
                                 fleet_tag(version, item.arch), item.layer, labels))
    return FleetReleasePlan(version=version, registry=registry, images=tuple(images))


# --------------------------------------------------------------------------- the release record


@dataclass(frozen=True)
class ReleaseRecord:
    """What a fleet release pushed, by digest: what a fleet engine deploys (never a tag, which can move)."""

    version: str
    registry: str
    #: component -> arch -> ``<registry>/<repo>@sha256:<64 hex>``
    components: Mapping[str, Mapping[str, str]]
    #: arch -> the base image's digest reference (discovery servers run it)
    base: Mapping[str, str]

    def component_ref(self, component: str, arch: str) -> str:
        """The digest reference of ``component``'s image for ``arch`` (UsageError when the release has none)."""
        found = self.components.get(component, {}).get(arch)
        if found is None:
            have = ", ".join(f"{c}/{a}" for c, arches in sorted(self.components.items()) for a in sorted(arches))
            raise UsageError(f"release {self.version} has no image of component {component!r} for {arch} "
                             f"(it has: {have or 'none'})", hint=f"run `release --fleet --tag {self.version}` again")
        return found

    def base_ref(self, arch: str) -> str:
        """The digest reference of the base image for ``arch`` (UsageError when the release has none)."""
        found = self.base.get(arch)
        if found is None:
            raise UsageError(f"release {self.version} has no base image for {arch} (it has: "
                             f"{', '.join(sorted(self.base)) or 'none'})")
        return found

    def to_json(self) -> str:
        """The record as the file holds it."""
        return json.dumps({"format": RECORD_FORMAT, "version": self.version, "registry": self.registry,
                           "components": {c: dict(a) for c, a in self.components.items()},
                           "base": dict(self.base)}, indent=2, sort_keys=True) + "\n"


def digest_ref(target: str, digest: str) -> str:
    """``target@digest`` (``<registry>/<repo>@sha256:...``), checked; ValueError when it is not one."""
    ref = f"{target}@{digest}"
    if not is_digest_ref(ref):
        raise ValueError(f"not a digest reference: {ref!r}")
    return ref


def is_digest_ref(text: str) -> bool:
    """True for ``[registry/]repo@sha256:<64 lower-case hex>`` (Docker's reference grammar, no tag)."""
    name, at, digest = text.partition("@")
    return bool(at) and ":" not in name.rsplit("/", 1)[-1] and re.fullmatch(IMAGE_REF, text) is not None \
        and _SHA256.fullmatch(at + digest) is not None


def parse_release_record(text: str, file: str) -> ReleaseRecord:
    """A release record from its file's ``text``; a UsageError naming ``file`` when it is not one (a hand-edited
    or truncated file is refused, never half-read)."""

    def bad(why: str) -> UsageError:
        return UsageError(f"{file}: not a release record: {why}", hint="run `release --fleet --tag V` again")

    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise bad(f"not JSON ({exc.msg} at line {exc.lineno})") from None
    except RecursionError:
        raise bad("nested too deeply") from None
    if not isinstance(data, dict) or data.get("format") != RECORD_FORMAT:
        raise bad(f"format {data.get('format') if isinstance(data, dict) else None!r}, not {RECORD_FORMAT}")
    version, registry = data.get("version"), data.get("registry")
    if not isinstance(version, str) or not naming.is_image_tag(version):
        raise bad("version is not an image tag")
    if not isinstance(registry, str) or not registry:
        raise bad("no registry")
    components, base = data.get("components"), data.get("base")
    if not isinstance(components, dict) or not isinstance(base, dict):
        raise bad("components and base must be mappings")
    refs = [ref for arches in components.values() if isinstance(arches, dict) for ref in arches.values()]
    if any(not isinstance(arches, dict) for arches in components.values()) or not all(
            isinstance(ref, str) and is_digest_ref(ref) for ref in [*refs, *base.values()]):
        raise bad("every image must be a digest reference (<registry>/<repo>@sha256:<64 hex>)")
    return ReleaseRecord(version=version, registry=registry,
                         components={str(c): {str(a): str(r) for a, r in arches.items()}
                                     for c, arches in components.items()},
                         base={str(a): str(r) for a, r in base.items()})
