"""The layers of a component's fleet image: one per ROS package of its install tree, so a release ships what
changed (pure).

``release --fleet`` once put a component's whole install tree (and its read-only project files) in **one**
layer: a one-line change in one package made every robot pull the whole tree again. Now the tree is cut where
colcon cuts it (an isolated install tree holds one folder per package):

1. the install tree's own files (``setup.bash``, ``_local_setup_util_*.py``, ...): made by colcon, rarely changed;
2. each package's ``share/`` (its manifest, environment hooks, ament index and CMake configs), then each
   package's code (``lib/``, ``bin/``, ``include/``, ...), the packages that others depend on first (colcon's own
   dependency records, ``share/colcon-core/packages/<pkg>``), ties in name order: interface and library packages
   change less often than the nodes built on them, a package's metadata less often than its code, and Docker
   Engine keeps a layer only when every layer below it is the same (it stores layers by chain), so what changes
   most goes last. Past :data:`MAX_LAYERS` a package is one layer, and then the lowest packages share one;
3. one layer per read-only project volume (``./config:/params:ro``), last: parameters change most often.

Every layer is a tar robocore writes itself (:mod:`robocore.adapters.image_layers`): entries in name order, owner
root, fixed times and modes, so the same files give the same bytes, the same layer digest and (with the same
parent image) the same image digest on any machine, whatever the build cache holds. A merged install tree
(``colcon build --merge-install``) has no package folders: it stays one layer.
"""

from __future__ import annotations

import heapq
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

from robocore.plan.fleet_release import LayerFile

#: The most layers robocore adds to one image. Docker Engine refuses an image of more than 127 layers, and every
#: layer is one more lower folder of the container's overlay mount on the robot.
MAX_LAYERS = 48
#: Where colcon records each package's run dependencies in an isolated install tree: ``<pkg>/`` + this + ``<pkg>``.
COLCON_PACKAGES = "share/colcon-core/packages"


@dataclass(frozen=True)
class Layer:
    """One layer of a fleet image: what it is (shown in the image's history) and the files it carries."""

    name: str
    files: tuple[LayerFile, ...]


def order_packages(depends: Mapping[str, Collection[str]]) -> list[str]:
    """The packages of ``depends`` (package -> the packages it depends on), each after those it depends on, ties
    (and cycles, which colcon refuses anyway) in name order. Dependencies outside ``depends`` are ignored."""
    waiting = {name: {d for d in deps if d in depends and d != name} for name, deps in depends.items()}
    ready = [name for name, deps in waiting.items() if not deps]
    heapq.heapify(ready)
    done: list[str] = []
    while len(done) < len(waiting):
        if not ready:  # a cycle: take the first name left
            ready = [min(n for n in waiting if n not in done)]
        name = heapq.heappop(ready)
        if name in done:
            continue
        done.append(name)
        for other, deps in waiting.items():
            if name in deps:
                deps.discard(name)
                if not deps and other not in done:
                    heapq.heappush(ready, other)
    return done


@dataclass(frozen=True)
class InstallTree:
    """What :func:`component_layers` needs to know of an install tree (read by the command)."""

    root: Path
    target: PurePosixPath
    #: package folder -> the packages it depends on (colcon's records); empty for a merged tree
    packages: Mapping[str, Collection[str]]
    #: every other entry at the tree's top (colcon's setup scripts, a merged tree's folders), by name
    others: Sequence[str]
    #: package folder -> the entries at its top (``share``, ``lib``, ``bin``, ...)
    contents: Mapping[str, Sequence[str]] = field(default_factory=dict)


def _package_layers(install: InstallTree, names: Sequence[str], *, split: bool) -> list[Layer]:
    """The layers of the packages ``names`` (in order): with ``split``, every package's ``share/`` (manifests,
    hooks, CMake configs: changed with the package's interface) below every package's code (``lib/``, ``bin/``,
    ...: what a one-line change touches); else one layer each."""
    def files(name: str, entries: Sequence[str]) -> tuple[LayerFile, ...]:
        return tuple(LayerFile(install.root / name / e, install.target / name / e) for e in sorted(entries))

    if not split:
        return [Layer(f"package {name}", (LayerFile(install.root / name, install.target / name),)) for name in names]
    meta = [Layer(f"package {name}: share", files(name, ["share"])) for name in names
            if "share" in install.contents.get(name, ())]
    code = [Layer(f"package {name}", files(name, [e for e in install.contents.get(name, ()) if e != "share"]))
            for name in names]
    return meta + [layer for layer in code if layer.files]


def component_layers(files: Sequence[LayerFile], install: InstallTree | None) -> tuple[Layer, ...]:
    """The layers of a component's fleet image carrying ``files`` (:func:`~robocore.plan.fleet_release.layer_files`:
    the install tree, then the read-only project volumes), ``install`` the install tree's listing (None without a
    workspace): see the module for the order. At most :data:`MAX_LAYERS`: past that, packages are not split, and
    then the lowest packages share one layer."""
    layers: list[Layer] = []
    for item in files:
        if install is not None and item.source == install.root and install.packages:
            top = tuple(LayerFile(install.root / name, install.target / name) for name in sorted(install.others))
            if top:
                layers.append(Layer(f"install tree {install.target}: colcon's files", top))
            names = order_packages(install.packages)
            budget = MAX_LAYERS - len(layers) - (len(files) - 1)
            if 2 * len(names) <= budget:
                layers += _package_layers(install, names, split=True)
                continue
            if len(names) > budget:  # the lowest packages (depended on most, changed least) in one layer
                low, names = names[:len(names) - budget + 1], names[len(names) - budget + 1:]
                layers.append(Layer(f"packages {', '.join(low)}", tuple(
                    LayerFile(install.root / name, install.target / name) for name in low)))
            layers += _package_layers(install, names, split=False)
        elif install is not None and item.source == install.root:
            layers.append(Layer(f"install tree {install.target}", (item,)))
        else:
            layers.append(Layer(f"project files {item.target}", (item,)))
    return tuple(layers)


# --------------------------------------------------------------------------- the image's configuration


def layered_config(parent: Mapping[str, object], history: Sequence[Mapping[str, object]], diff_ids: Sequence[str],
                   names: Sequence[str], labels: Mapping[str, str]) -> dict[str, object]:
    """The image configuration of ``parent`` (its ``docker image inspect``) with the layers ``diff_ids`` (named
    ``names``) on top and ``labels`` added. ``history`` is the parent's (``docker history``, newest first). Nothing
    in it depends on when or where it is made (``created`` is the parent's), so the same parent and layers give the
    same image ID, and a release is reproducible. The parent's steps keep their times but not their commands:
    every robot pulls the configuration of every new image, and a component image's commands (its apt line,
    the base's set-up) were most of it (6.4 kB of a talker's with a compiler); the code-less image on the
    machine that released it shows them (``docker history <repo>:latest``)."""
    config = dict(parent.get("Config") or {})  # type: ignore[call-overload]
    config["Labels"] = {**(config.get("Labels") or {}), **labels}
    created = str(parent.get("Created") or "1970-01-01T00:00:00Z")
    steps: list[dict[str, object]] = []
    for entry in reversed(history):
        step: dict[str, object] = {"created": _rfc3339(entry.get("Created"))}
        if not entry.get("Size"):
            step["empty_layer"] = True  # a layer of 0 bytes counts as empty: never more history than layers
        steps.append(step)
    steps += [{"created": created, "created_by": f"robocore release --fleet: {name}"} for name in names]
    rootfs = parent.get("RootFS") or {}
    parent_layers = list(rootfs.get("Layers") or []) if isinstance(rootfs, Mapping) else []
    out: dict[str, object] = {
        "architecture": parent.get("Architecture", ""), "os": parent.get("Os", "linux"), "created": created,
        "config": config, "rootfs": {"type": "layers", "diff_ids": [*parent_layers, *diff_ids]}, "history": steps,
    }
    if parent.get("Variant"):
        out["variant"] = parent["Variant"]
    return out


def _rfc3339(seconds: object) -> str:
    import datetime

    value = seconds if isinstance(seconds, (int, float)) else 0
    return datetime.datetime.fromtimestamp(value, datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
