"""Self-contained release images for a fleet, and the release record that names them by digest (pure).

A single robot gets its code by ``sync`` (install trees beside code-less images). A fleet engine runs
images only, so ``release --fleet --tag V`` pushes, per component (and its host's arch), the
component's staged image plus layers holding what ``sync`` would ship for it (one per ROS package of the install
tree, then one per project volume: :mod:`robocore.plan.fleet_layers`):

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

from robocore.config.model import Arch, Component, read_only_project_path
from robocore.config.values import IMAGE_REF, NAME
from robocore.errors import UsageError
from robocore.plan import naming

#: Suffix of a fleet image's tag (``V-<arch>-fleet``): the code-less release of the same version is ``V-<arch>``.
FLEET_TAG_SUFFIX = "fleet"
#: Version of the release record's format.
RECORD_FORMAT = 1
#: The label the layer carries: the component it is of. Not the release: a label is part of the image's
#: configuration, so a release label would give a component whose code did not change a new digest in every
#: release, and every robot would replace it ("no churn" would never apply). The record and the tags say the release.
LABEL_COMPONENT = "dev.robocore.component"

_SHA256 = re.compile(r"@sha256:[0-9a-f]{64}")
#: The arches a record names images for (robot.yaml's hosts' ``arch``).
_ARCHES = tuple(arch.value for arch in Arch)


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
    layer files gets its layers and a label naming its component: the same content gives the same image (robocore
    writes the layers byte for byte the same) and so the same digest in every release."""
    prefix = registry.rstrip("/")
    images = []
    for item in sources:
        labels = {LABEL_COMPONENT: item.component} if item.layer else {}
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
    except ValueError:  # a number of more digits than Python converts (4,300)
        raise bad("a number too long to read") from None
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
    arch_keys = [a for arches in components.values() if isinstance(arches, dict) for a in arches] + list(base)
    if not all(re.fullmatch(NAME, c) for c in components) or not all(a in _ARCHES for a in arch_keys):
        raise bad(f"components are named as in robot.yaml and images by arch ({', '.join(_ARCHES)})")
    refs = [ref for arches in components.values() if isinstance(arches, dict) for ref in arches.values()]
    if any(not isinstance(arches, dict) for arches in components.values()) or not all(
            isinstance(ref, str) and is_digest_ref(ref) for ref in [*refs, *base.values()]):
        raise bad("every image must be a digest reference (<registry>/<repo>@sha256:<64 hex>)")
    return ReleaseRecord(version=version, registry=registry,
                         components={str(c): {str(a): str(r) for a, r in arches.items()}
                                     for c, arches in components.items()},
                         base={str(a): str(r) for a, r in base.items()})


def record_problems(record: ReleaseRecord, registry: str, base: str, components: Mapping[str, str]) -> list[
        tuple[str, str]]:
    """Why ``record`` may not be believed for a fleet whose images live in ``registry`` (fleet.yaml's, else
    robot.yaml's): ``(key, problem)`` for the record's registry when it is another, and for each image outside
    ``registry`` or whose repository is not that image's (``base``, the base image's repository; ``components``,
    each component's name -> its image's repository). A record names exactly the images a release pushed, so any
    other reference (another registry, Docker Hub, another component's image) is refused, never run."""
    prefix = registry.rstrip("/")
    found: list[tuple[str, str]] = []
    if record.registry.rstrip("/") != prefix:
        found.append(("registry", f"{record.registry!r} is not the fleet's registry {registry!r}"))
    wanted = [(f"base.{arch}", ref, base) for arch, ref in sorted(record.base.items())]
    for component, arches in sorted(record.components.items()):
        if component not in components:
            found.append((f"components.{component}", f"{component!r} is not a component of robot.yaml"))
            continue
        wanted += [(f"components.{component}.{arch}", ref, components[component])
                   for arch, ref in sorted(arches.items())]
    for key, ref, repository in wanted:
        name = ref.split("@", 1)[0]
        if name != f"{prefix}/{repository}":
            where = "not that image's repository" if name.startswith(prefix + "/") else "outside the fleet's registry"
            found.append((key, f"{name!r} is {where} (expected {prefix}/{repository}@sha256:...)"))
    return found
