"""The records commands leave in ``.robocore/`` for each other, read and written here only.

- build state (``build``): per component, the package hashes, source files and plain copies of its
  last successful colcon build; ``build`` plans the next build from it, ``run`` and the compose
  files label a local component's container with its digest;
- synced releases (``sync``): per host, the release id and tree digest each component last received;
  ``run`` labels a remote component's container with its release, ``rollback`` rewrites it;
- release history (``run``, ``rollback``): per host, what each run deployed (tag and releases).

Where each record lives is :class:`~robocore.project.ProjectFolder`'s business. A record that is
missing or unreadable reads as empty: it is a cache of what happened, never an input a user wrote.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Mapping, Sequence
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from robocore.config.model import Host
from robocore.files import MAX_STATE_RECORD_BYTES, read_own_file, write_atomic
from robocore.plan.containers import ContainerSpec
from robocore.plan.naming import ROLE_COMPONENT
from robocore.project import Project

#: Label of a local component's container: the state of the build it runs (see :func:`with_local_build`).
LABEL_BUILD = "dev.robocore.build"
#: Label carrying the release a remote component's container was started on (see :func:`with_synced_release`).
LABEL_RELEASE = "dev.robocore.release"
#: Runs kept per host in the release history.
HISTORY_KEEP = 20


def _read_json(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(read_own_file(path, limit=MAX_STATE_RECORD_BYTES) or b"{}")  # nor a link, a FIFO, a huge file
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


# --------------------------------------------------------------------------- build state


def read_build_state(path: Path) -> dict[str, Any]:
    """The build state in ``path`` (a project's ``build_state_file``), empty when there is none."""
    return _read_json(path)


def write_build_state(path: Path, state: Mapping[str, Any]) -> None:
    """Replace the build state in ``path`` atomically."""
    write_atomic(path, json.dumps(state, indent=1, sort_keys=True))


def with_local_build(project: Project, host: Host, specs: Sequence[ContainerSpec]) -> list[ContainerSpec]:
    """Add the state of each local component's last build to its spec's labels.

    Local containers mount ``.robocore/build/<c>/install`` in place, so a rebuild changes
    nothing in the spec; without this label ``run`` would keep the container on the code it
    loaded at start. The build writes its state file after each success.
    """
    if not host.is_local:
        return list(specs)
    out = []
    for spec in specs:
        if spec.role == ROLE_COMPONENT:
            # never followed through a link, never blocking on a FIFO, bounded
            state = read_own_file(project.build_state_file(spec.service), limit=MAX_STATE_RECORD_BYTES) or b""
            if state:
                digest = hashlib.sha256(state).hexdigest()[:16]
                spec = dataclasses.replace(spec, extra_labels=(*spec.extra_labels, (LABEL_BUILD, digest)))
        out.append(spec)
    return out


# --------------------------------------------------------------------------- synced releases


def read_synced(project: Project, host: str) -> dict[str, dict[str, Any]]:
    """Component -> ``{"release": id, "digest": tree digest}`` last synced to ``host`` (empty when never)."""
    comps = _read_json(project.sync_state_file(host)).get("components", {})
    return {k: v for k, v in comps.items() if isinstance(v, dict)} if isinstance(comps, dict) else {}


def write_synced(project: Project, host: str, components: Mapping[str, Mapping[str, Any]]) -> None:
    """Record what ``host`` now has, per component."""
    text = json.dumps({"host": host, "components": components}, indent=2) + "\n"
    write_atomic(project.sync_state_file(host), text)


def synced_releases(project: Project, host: str) -> dict[str, str]:
    """Component -> release id last synced to ``host`` (empty when never synced)."""
    return {name: str(entry.get("release", "")) for name, entry in read_synced(project, host).items()}


def with_synced_release(project: Project, host: Host, specs: Sequence[ContainerSpec]) -> list[ContainerSpec]:
    """Add the synced release id of each remote component to its spec's labels.

    The container mounts ``<component>/current/install``, a path that stays the same across
    releases, so without this a sync would not change the spec hash and ``run`` would keep
    the container on the old files. Local hosts (files used in place) are unchanged.
    """
    if host.is_local:
        return list(specs)
    releases = synced_releases(project, host.name)
    out = []
    for spec in specs:
        release = releases.get(spec.service) if spec.role == ROLE_COMPONENT else None
        if release:
            spec = dataclasses.replace(spec, extra_labels=(*spec.extra_labels, (LABEL_RELEASE, release)))
        out.append(spec)
    return out


# --------------------------------------------------------------------------- release history


def history(project: Project, host: str) -> list[dict[str, Any]]:
    """The recorded runs of ``host`` (oldest first; empty when none)."""
    runs = _read_json(project.history_file(host)).get("runs", [])
    return [r for r in runs if isinstance(r, dict)] if isinstance(runs, list) else []


def record_run(project: Project, host: Host, tag: str | None) -> None:
    """Append what ``host`` runs now (tag and synced releases) unless it equals the last entry;
    the last :data:`HISTORY_KEEP` runs are kept."""
    releases = {} if host.is_local else synced_releases(project, host.name)
    releases = {c.name: releases[c.name] for c in project.robot.components_on(host.name) if c.name in releases}
    entry = {"tag": tag, "releases": releases}
    runs = history(project, host.name)
    if runs and {"tag": runs[-1].get("tag"), "releases": runs[-1].get("releases", {})} == entry:
        return
    runs.append({**entry, "time": datetime.now(timezone.utc).isoformat(timespec="seconds")})
    write_atomic(project.history_file(host.name),
                 json.dumps({"host": host.name, "runs": runs[-HISTORY_KEEP:]}, indent=2) + "\n")
