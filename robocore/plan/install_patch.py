"""Which source edits can skip colcon: files colcon copied verbatim into the build output (pure).

colcon installs many files of a package unchanged: the modules of an ``ament_python`` package
(``<pkg>/talker.py`` -> ``install/<pkg>/lib/python3.X/site-packages/<pkg>/talker.py``), launch
and config files (``launch/x.launch.py`` -> ``install/<pkg>/share/<pkg>/launch/x.launch.py``).
After every colcon build, robocore records for each source file the output files that are
byte-identical copies of it at a path ending with its package-relative path. When the next
edit only changes such files, ``build`` writes the new contents over those copies instead of
starting a colcon container: the result is what colcon would have installed, in a fraction of
the time.

It falls back to colcon whenever that could differ: a file added, removed or made executable,
a build description changed (``package.xml``, ``setup.py``, ``CMakeLists.txt``, ...), a file
that code is generated or compiled from (``.msg``, ``.srv``, headers, ...), a changed file with
no recorded copy (compiled, generated or not installed), or an output that no longer holds the
content recorded for it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

#: Files that describe how a package is built: changing one always runs colcon.
BUILD_DESCRIPTIONS = frozenset({
    "package.xml", "setup.py", "setup.cfg", "pyproject.toml", "CMakeLists.txt", "colcon.pkg", "COLCON_IGNORE",
    "AMENT_IGNORE", "CATKIN_IGNORE", "MANIFEST.in", "requirements.txt",
})
#: Suffixes of files that are build descriptions wherever they are.
BUILD_SUFFIXES = (".cmake", ".cmake.in")
#: Suffixes of files that code is generated or compiled from: installed as they are too (interface
#: definitions under ``share/<pkg>/msg``, headers under ``include/``), but an edit must regenerate and
#: recompile, so it always runs colcon.
COMPILED_SUFFIXES = (".msg", ".srv", ".action", ".idl", ".h", ".hh", ".hpp", ".hxx", ".inl", ".c", ".cc", ".cpp",
                     ".cxx")

#: ``{package-relative path: (content digest, executable)}`` for one package's sources.
PackageFiles = Mapping[str, tuple[str, bool]]


@dataclass(frozen=True)
class Patch:
    """New contents of one source file, to be written over its recorded copies."""

    package: str
    source: str  # package-relative path of the edited file
    digest: str  # its new content digest
    old_digest: str  # what each target holds now
    targets: tuple[str, ...]  # paths relative to the component's build output folder


def is_build_description(rel: str) -> bool:
    """Whether a package-relative path is a file that tells colcon how to build the package."""
    name = rel.rsplit("/", 1)[-1]
    return name in BUILD_DESCRIPTIONS or name.endswith(BUILD_SUFFIXES)


def is_compiled(rel: str) -> bool:
    """Whether a package-relative path is a file that code is generated or compiled from."""
    return rel.endswith(COMPILED_SUFFIXES)


def verbatim_copies(package: str, sources: PackageFiles, outputs: Mapping[str, str]) -> dict[str, list[str]]:
    """Source path -> output paths of ``package`` (under ``install/<package>/`` or ``build/<package>/``)
    that hold the same bytes at a path ending with ``/<source path>``.

    ``outputs`` maps output paths (relative to the build output folder) to content digests; only
    candidates need to be in it (files whose name matches a source file's name).
    """
    own = (f"install/{package}/", f"build/{package}/")
    by_name: dict[str, list[str]] = {}
    for out in sorted(outputs):
        if out.startswith(own):
            by_name.setdefault(out.rsplit("/", 1)[-1], []).append(out)
    copies: dict[str, list[str]] = {}
    for rel, (digest, _) in sorted(sources.items()):
        if is_build_description(rel) or is_compiled(rel):
            continue
        found = [out for out in by_name.get(rel.rsplit("/", 1)[-1], [])
                 if out.endswith("/" + rel) and outputs[out] == digest]
        if found:
            copies[rel] = found
    return copies


def plan_patches(
    changed: list[str],
    before: Mapping[str, PackageFiles],
    now: Mapping[str, PackageFiles],
    copies: Mapping[str, Mapping[str, list[str]]],
) -> tuple[list[Patch], str]:
    """The patches that bring the build output of the ``changed`` packages up to date.

    Returns ``(patches, "")`` when every change is a verbatim copy, else ``([], reason)`` with the
    first reason colcon is needed.
    """
    patches: list[Patch] = []
    for package in changed:
        old, new = before.get(package), now.get(package)
        if old is None or new is None:
            return [], f"{package}: no file list from the last build"
        if set(old) != set(new):
            added = sorted(set(new) - set(old))
            return [], f"{package}: {'file added: ' + added[0] if added else 'file removed'}"
        for rel in sorted(new):
            if new[rel] == old[rel]:
                continue
            if new[rel][1] != old[rel][1]:
                return [], f"{package}: {rel} changed its executable bit"
            if is_build_description(rel):
                return [], f"{package}: {rel} describes the build"
            if is_compiled(rel):
                return [], f"{package}: code is generated or compiled from {rel}"
            targets = copies.get(package, {}).get(rel)
            if not targets:
                return [], f"{package}: {rel} is not installed as a plain copy"
            patches.append(Patch(package, rel, new[rel][0], old[rel][0], tuple(targets)))
    if not patches:
        return [], "no file content changed"
    return patches, ""
