"""What each robot will pull for a rollout, said before it starts: from the registry's manifests, the layers of the
release's images that are not in the images the robot runs now (:mod:`robocore.plan.pull_bytes`).

On Wi-Fi and LTE that is what a rollout costs; ``fleet rollout`` prints it per group of robots that pull the same
(one line for a fleet of alike robots, however large), e.g. ``r2, r3, r4: 6.8 kB of 420.1 MB``. The manifests are
read from this machine with the Docker CLI (the user's registry credentials and trust, as ``release --fleet``
pushes), once per image. A robot that runs nothing of the project yet pulls the whole (``at most``: it may hold
the base already). When a manifest cannot be read, the rollout goes on and says why the bytes are unknown.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from robocore.adapters import swarm
from robocore.commands.fleet_swarm import FleetProject, project_label
from robocore.commands.support.reporting import Reporter
from robocore.errors import RobocoreError
from robocore.plan import swarm_services as plan
from robocore.plan.pull_bytes import ImageLayers, RobotBytes, human, robot_bytes

if TYPE_CHECKING:
    import docker


@dataclass(frozen=True)
class RobotPull:
    """The bytes one robot will pull for a rollout (``fleet rollout --json`` lists them first)."""

    kind: ClassVar[str] = "fleet_robot_pull"
    robot: str
    release: str
    pull_bytes: int
    whole_bytes: int
    known: bool


def robots_bytes(targets: Mapping[str, Sequence[str]], held: Mapping[str, Sequence[str]],
                 manifest: Callable[[str], ImageLayers]) -> list[RobotBytes]:
    """Per robot of ``targets`` (robot -> the images of the release it will run): the bytes it pulls, given
    ``held`` (robot -> the images it runs now; none: unknown) and ``manifest`` (an image's layers)."""
    cache: dict[str, ImageLayers] = {}

    def layers(ref: str) -> ImageLayers:
        if ref not in cache:
            cache[ref] = manifest(ref)
        return cache[ref]

    out = []
    for robot, refs in targets.items():
        mine = held.get(robot) or []
        out.append(robot_bytes(robot, [layers(r) for r in sorted(set(refs))],
                               [layers(r) for r in sorted(set(mine))] if mine else None))
    return out


def lines(found: Sequence[RobotBytes]) -> list[str]:
    """One line per group of robots that pull the same: ``r2, r3: 6.8 kB of 420.1 MB``."""
    groups: dict[tuple[int, int, bool], list[str]] = {}
    for item in found:
        groups.setdefault((item.pull, item.whole, item.known), []).append(item.robot)
    out = []
    for (pull, whole, known), robots in sorted(groups.items(), key=lambda kv: kv[1][0]):
        names = ", ".join(robots[:8]) + (f" and {len(robots) - 8} more" if len(robots) > 8 else "")
        what = f"{human(pull)} of {human(whole)}" if known else f"at most {human(whole)} (runs nothing of it yet)"
        out.append(f"  {names}: {what}")
    return out


def report_bytes(client: docker.DockerClient, fleet: FleetProject, release: plan.Release, robots: Sequence[str],
                 reporter: Reporter) -> list[RobotPull]:
    """Say what each robot of ``robots`` will pull to run ``release`` (see the module); the figures."""
    from robocore.adapters import docker_manifest
    from robocore.adapters.docker_hosts import local_client
    from robocore.plan.release import plain_http

    registry = fleet.fleet.registry_for(fleet.project.robot) or ""
    try:
        local = local_client()
        try:
            insecure = plain_http(registry, local.info().get("RegistryConfig") or {})
        finally:
            local.close()
        held: dict[str, list[str]] = {}
        for service in swarm.services(client, project_label(fleet)):
            robot = service.labels.get(plan.LABEL_ROBOT, "")
            image = service.labels.get(plan.LABEL_IMAGE) or service.image
            if robot and "@sha256:" in image and plan.LABEL_PROBE not in service.labels:
                held.setdefault(robot, []).append(image)
        targets = {robot: [s.image for s in plan.robot_services(fleet.project, robot, fleet.instances[robot],
                                                                release)] for robot in robots}
        found = robots_bytes(targets, held, lambda ref: docker_manifest.image_layers(ref, insecure=insecure))
    except RobocoreError as exc:
        reporter.info(f"bytes each robot will pull: unknown ({exc.message})")
        return []
    reporter.info(f"bytes each robot will pull for {release.version} (from the registry's manifests):")
    for line in lines(found):
        reporter.info(line)
    return [RobotPull(f.robot, release.version, f.pull, f.whole, f.known) for f in found]
