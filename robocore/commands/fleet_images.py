"""The images of a fleet release: the release record ``.robocore/releases/<VERSION>.json`` that ``release`` writes.

The record maps each component (and the base image, which discovery servers and the health probe run) to one
image per arch, by digest (``repo@sha256:...``), so that every robot runs exactly what was pushed.
"""

from __future__ import annotations

import json
import re

from robocore.errors import UsageError
from robocore.plan.swarm_services import Release
from robocore.project import Project

#: An image reference pinned by digest.
BY_DIGEST = re.compile(r"^[^\s@]+@sha256:[0-9a-f]{64}$")
#: The key of the base image (discovery servers and the health probe run it).
BASE = "base"


def release_images(project: Project, version: str) -> Release:
    """The release record of ``version`` (a UsageError naming the file when it is missing or malformed)."""
    path = project.state_dir / "releases" / f"{version}.json"
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise UsageError(f"no release record {path}", hint=f"robocore release --tag {version} --fleet") from None
    except (OSError, ValueError) as exc:
        raise UsageError(f"{path}: not a release record ({exc})") from None
    images = data.get("components") if isinstance(data, dict) else None
    base_images = data.get("base") if isinstance(data, dict) else None
    if not isinstance(images, dict) or not isinstance(base_images, dict):
        raise UsageError(f"{path}: not a release record (no components or base)")
    components: dict[str, dict[str, str]] = {}
    for name, arches in {**images, BASE: base_images}.items():
        if not isinstance(arches, dict) or not all(isinstance(r, str) and BY_DIGEST.match(r) for r in arches.values()):
            raise UsageError(f"{path}: images.{name}: each arch needs an image by digest (repo@sha256:...)")
        components[str(name)] = {str(a): str(r) for a, r in arches.items()}
    base = components.pop(BASE, {})
    return Release(version=version, components=components, base=base)
