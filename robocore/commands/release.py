"""release and rollback: versioned images in a registry, and going back to what ran before.

``release [--tag V]`` tags the base image and every staged component image as
``<registry>/<image>:V`` (default V: ``git describe --tags --always --dirty`` of the project)
and pushes them to ``robot.yaml``'s ``registry``. ``run --tag V`` then deploys those images.

Every successful ``run`` appends what a host now runs (image tag, synced release per
component) to ``.robocore/history/<host>.json`` (last 20 entries). ``rollback`` takes each
host back to the entry before the last one: it switches each component's ``current`` symlink
back to the release it ran then (still on the host: sync keeps the last releases) and re-runs
that host with the tag it ran then. A rollback is itself recorded, so a second rollback
returns to where the first one started.
"""

from __future__ import annotations

import json
import subprocess
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from robocore.commands.context import Options
from robocore.config.model import Host
from robocore.errors import DockerError, GroupError, HostError, RobocoreError, UsageError
from robocore.files import write_atomic
from robocore.plan import naming
from robocore.project import Project

HISTORY_KEEP = 20

# $1 = component root, $2 = release id: point current at an existing release, atomically.
_SWITCH_SCRIPT = """\
set -eu
cd -- "$1"
[ -d "releases/$2" ] || { echo "release $2 is no longer on this host" >&2; exit 3; }
rm -f -- .current.tmp
ln -s -- "releases/$2" .current.tmp
mv -T -- .current.tmp current
"""


# --------------------------------------------------------------------------- release


def default_tag(project: Project) -> str:
    """``git describe --tags --always --dirty`` of the project folder."""
    try:
        proc = subprocess.run(["git", "describe", "--tags", "--always", "--dirty"], cwd=project.root,
                              capture_output=True, text=True, timeout=30, check=False)
    except FileNotFoundError:
        raise UsageError("git is not installed, so there is no default version", hint="pass --tag V") from None
    if proc.returncode != 0:
        raise UsageError(f"{project.root} is not a git repository with a commit, so there is no default version",
                         hint="pass --tag V, or commit the project to git")
    return proc.stdout.strip()


def released_images(project: Project) -> list[str]:
    """Local repositories (no tag) that a release carries: the base and every built component image."""
    robot = project.robot
    images = [naming.base_image(robot, project.name)]
    images += [naming.component_image(robot, project.name, c.name) for c in robot.components if not c.image]
    return images


def release(options: Options, *, tag: str | None) -> None:
    """Tag every image of the project with a version and push it to the registry."""
    from robocore.ui import console, stdout

    project = options.load()
    robot = project.robot
    if not robot.registry:
        raise UsageError(f"{project.robot_file}: release needs a registry (registry: HOST[:PORT][/PATH])",
                         hint="without a registry, `run` streams images to each host instead")
    version = tag or default_tag(project)
    if not naming.is_image_tag(version):
        raise UsageError(f"{version!r} is not a valid image tag", hint="letters, digits, '_', '.', '-' (max 128)")
    plan = [(f"{repo}:latest", naming.registry_image(robot, repo), version) for repo in released_images(project)]
    if options.dry_run:
        for source, target, v in plan:
            stdout().print(f"docker tag {source} {target}:{v} && docker push {target}:{v}", markup=False)
        return
    from docker.errors import APIError, ImageNotFound

    from robocore.adapters.docker_hosts import local_client
    from robocore.adapters.image_delivery import check_stream

    client = local_client(timeout=1800)
    pushed = []
    for source, target, v in plan:
        try:
            image = client.images.get(source)
        except ImageNotFound:
            raise UsageError(f"image {source} does not exist", hint="run `prepare-base` and `stage` first") from None
        image.tag(target, v)
        try:
            check_stream(client.images.push(target, v, stream=True, decode=True), f"push {target}:{v}")
        except APIError as exc:
            raise DockerError(f"push {target}:{v} failed: {exc.explanation or exc}",
                              hint=f"is the registry {robot.registry} reachable (and trusted) from this machine?"
                              ) from None
        pushed.append(f"{target}:{v}")
        if not options.quiet:
            console().print(f"pushed {target}:{v}", markup=False)
    if options.json:
        print(json.dumps({"tag": version, "pushed": pushed}, indent=2), flush=True)
    elif not options.quiet:
        console().print(f"released {version}: deploy it with `run --tag {version}`", markup=False)


# --------------------------------------------------------------------------- history


def history_file(project: Project, host: str) -> Path:
    """``.robocore/history/<host>.json``: what ``run`` deployed on ``host``, oldest first."""
    return project.state_dir / "history" / f"{host}.json"


def history(project: Project, host: str) -> list[dict[str, Any]]:
    """The recorded runs of ``host`` (oldest first; empty when none)."""
    try:
        data = json.loads(history_file(project, host).read_text())
    except (OSError, ValueError):
        return []
    runs = data.get("runs", []) if isinstance(data, dict) else []
    return [r for r in runs if isinstance(r, dict)]


def record_run(project: Project, host: Host, tag: str | None) -> None:
    """Append what ``host`` runs now (tag and synced releases) unless it equals the last entry."""
    from robocore.commands.sync import synced_releases

    releases = {} if host.is_local else synced_releases(project, host.name)
    releases = {c.name: releases[c.name] for c in project.robot.components_on(host.name) if c.name in releases}
    entry = {"tag": tag, "releases": releases}
    runs = history(project, host.name)
    if runs and {"tag": runs[-1].get("tag"), "releases": runs[-1].get("releases", {})} == entry:
        return
    runs.append({**entry, "time": datetime.now(timezone.utc).isoformat(timespec="seconds")})
    write_atomic(history_file(project, host.name),
                 json.dumps({"host": host.name, "runs": runs[-HISTORY_KEEP:]}, indent=2) + "\n")


# --------------------------------------------------------------------------- rollback


def rollback(options: Options, *, host: str | None) -> None:
    """Return each host (or ``--host``) to the version it ran before its last run."""
    from robocore.commands import run as run_cmd
    from robocore.ui import console

    project = options.load()
    hosts = run_cmd.select_hosts(project, host)
    targets: dict[str, dict[str, Any]] = {}
    for h in hosts:
        runs = history(project, h.name)
        if len(runs) >= 2:
            targets[h.name] = runs[-2]
        elif host:
            raise UsageError(f"host {h.name}: no earlier version recorded in {history_file(project, h.name)}",
                             hint="rollback needs two successful runs of this host")
    if not targets:
        raise UsageError("no host has an earlier version to return to", hint="rollback needs two successful runs")
    chosen = [h for h in hosts if h.name in targets]
    if options.dry_run:
        for h in chosen:
            t = targets[h.name]
            console().print(f"{h.name}: would run tag {t.get('tag') or 'latest'} with releases "
                            f"{t.get('releases') or '(local build output)'}", markup=False)
        return

    def work(h: Host) -> Any:
        target = targets[h.name]
        _restore_releases(project, h, target.get("releases", {}))
        from robocore.commands.sync import with_synced_release
        from robocore.plan.containers import host_specs

        tag = target.get("tag")
        specs = with_synced_release(project, h, host_specs(project, h.name, tag=tag))
        outcome = run_cmd.deploy_host(project, h, specs, dry_run=False, quiet=options.quiet)
        record_run(project, h, tag)
        return outcome

    results, failures = run_cmd.for_each_host(chosen, work)
    for name in sorted(results):
        t = targets[name]
        console().print(f"{name}: back to tag {t.get('tag') or 'latest'}"
                        + (f", releases {t['releases']}" if t.get("releases") else ""), markup=False)
    if failures:
        raise GroupError(failures, list(results))


def _restore_releases(project: Project, host: Host, releases: dict[str, str]) -> None:
    """Point each component's ``current`` back at ``releases[component]`` and record it as synced."""
    if host.is_local or not releases:
        return
    from robocore.adapters import ssh
    from robocore.commands.sync import _read_state, _write_state
    from robocore.plan.layout import component_root
    from robocore.plan.sync import is_release_id

    state = _read_state(project, host.name)
    for component, release_id in sorted(releases.items()):
        if not is_release_id(release_id):
            raise HostError(f"host {host.name}: history names an invalid release {release_id!r} for {component}")
        root = str(component_root(host, component))
        try:
            ssh.run(host, ["sh", "-c", _SWITCH_SCRIPT, "sh", root, release_id], timeout=60)
        except RobocoreError as exc:
            raise HostError(f"host {host.name}: cannot return {component} to release {release_id}: {exc.message}",
                            hint="sync keeps the last 3 releases; older ones are gone") from None
        state[component] = {"release": release_id, "digest": ""}
    _write_state(project, host.name, state)
