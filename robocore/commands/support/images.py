"""What prepare-base (:mod:`robocore.commands.prepare_base`) and stage (:mod:`robocore.commands.stage`) share: an
image plan with its resolved context and inputs hash, the decision to build it, and the builds themselves.

Images are rebuilt only when the content hash of their inputs (label ``dev.robocore.inputs``)
changes. A dry run contacts no daemon and fetches nothing: what it cannot know is
:data:`~robocore.commands.support.context.DRY_RUN_UNKNOWN`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from robocore.commands.support.context import DRY_RUN_UNKNOWN
from robocore.commands.support.hosts import in_parallel
from robocore.commands.support.machine import MAX_PARALLEL, local_docker, native_arch
from robocore.commands.support.reporting import Outcome, Reporter, report_outcomes
from robocore.config.model import Component
from robocore.errors import BuildError
from robocore.plan import discovery, naming
from robocore.plan.dockerfiles import ContextEntry, ImagePlan
from robocore.plan.inputs import inputs_hash
from robocore.project import Project

if TYPE_CHECKING:
    from robocore.adapters.image_builder import ContextFile, ImageState


def base_arches(project: Project, components: Sequence[Component] | None = None) -> list[str]:
    """The arches that need a base image: those the components (default: all) built from source run on, plus
    the discovery servers' hosts' (each runs the base of its host's arch) when all are asked; the native one when
    none is."""
    robot = project.robot
    comps = robot.components if components is None else components
    found = {robot.host(c.runs_on).arch.value for c in comps if c.image is None}
    if components is None:
        found |= {robot.host(s.host).arch.value for s in discovery.for_robot(robot).servers()}
    return sorted(found) or [native_arch()]


def allowed_protocol(entry: object) -> str | None:
    """A repository or common package's ``allow_protocol`` opt-in (``file``, ``ext``, ...), if it has one."""
    value = getattr(entry, "allow_protocol", None)
    return value if isinstance(value, str) else None


def fetch_source(project: Project, url: str, version: str | None, allow: str | None, *, refresh: bool,
                 dry_run: bool) -> Path | None:
    """The checkout of ``url`` at ``version`` (fetched unless cached; ``allow`` is the entry's protocol
    opt-in); in a dry run the cached one, or None when there is none yet (nothing is fetched)."""
    from robocore.adapters import vcs

    dest = project.cache_dir / "git" / vcs.cache_key(url, version)
    if dry_run:
        vcs.fetch_argv(url, version)  # the same checks as a fetch (a URL or version that is not one)
        return dest if (dest / ".git" / vcs.SOURCE_FILE).is_file() else None
    vcs.fetch(url, version, dest, refresh=refresh, allow_protocol=allow)
    return dest


def resource_entry(dest: str, name: str, *, executable: bool) -> ContextEntry:
    """A file of robocore's own resources, as a build context entry."""
    from robocore import resources

    return ContextEntry(dest=dest, data=resources.read(name), executable=executable)


@dataclass(frozen=True)
class Planned:
    """An image plan with its resolved context, inputs hash and decision."""

    plan: ImagePlan
    files: tuple[ContextFile, ...]
    parent_id: str
    inputs: str
    labels: dict[str, str]


def planned(project: Project, plan: ImagePlan, parent_id: str, *, known: bool = True) -> Planned:
    """``plan`` with its context files and inputs hash; the hash is :data:`DRY_RUN_UNKNOWN` when the parent
    image or a source is unknown (a dry run)."""
    from robocore.adapters.image_builder import expand

    files = tuple(expand(plan.context))
    digest = inputs_hash(plan.dockerfile, [f.digest() for f in files], parent=parent_id, platform=plan.platform,
                         extra={f"label {key}": value for key, value in plan.labels.items()})
    if not known or parent_id == DRY_RUN_UNKNOWN:
        digest = DRY_RUN_UNKNOWN
    labels = {**plan.labels, naming.LABEL_PROJECT: project.name, naming.LABEL_ROLE: plan.role,
              naming.LABEL_INPUTS: digest}
    if plan.component:
        labels[naming.LABEL_COMPONENT] = plan.component
    return Planned(plan=plan, files=files, parent_id=parent_id, inputs=digest, labels=labels)


def decide(state: ImageState | None, planned: Planned, *, force: bool) -> str | None:
    """Why the image must be built, or None when it is up to date (:data:`DRY_RUN_UNKNOWN` when a dry run
    cannot know)."""
    if force:
        return "--force"
    if planned.inputs == DRY_RUN_UNKNOWN:
        return DRY_RUN_UNKNOWN
    if state is None:
        return "not built yet"
    if state.labels.get(naming.LABEL_INPUTS) != planned.inputs:
        return "inputs changed"
    return None


def show_plan(report: Reporter, planned: Planned, reason: str | None) -> None:
    """A dry run's image: its reference, platform, inputs and decision, then its Dockerfile."""
    if reason == DRY_RUN_UNKNOWN:
        status = f"build or keep: {DRY_RUN_UNKNOWN}"
    else:
        status = f"would build ({reason})" if reason else "up to date"
    inputs = planned.inputs if planned.inputs == DRY_RUN_UNKNOWN else planned.inputs[:19]
    report.plain(f"# {planned.plan.ref} [{planned.plan.platform}] inputs {inputs}: {status}")
    report.plain(planned.plan.dockerfile)


def triage(planned: Planned, reason: str | None, dry_run: bool,
           outcomes: list[Outcome], work: list[tuple[Planned, str]]) -> None:
    """Up to date, would build (dry run) or queued for building: the one decision per image."""
    ref, role = planned.plan.ref, planned.plan.role
    plan = planned.plan.dockerfile if dry_run else None
    if reason is None:
        outcomes.append(Outcome(what=ref, role=role, action="up-to-date", plan=plan))
    elif reason == DRY_RUN_UNKNOWN:
        outcomes.append(Outcome(what=ref, role=role, action="unknown", reason=reason, plan=plan))
    elif dry_run:
        outcomes.append(Outcome(what=ref, role=role, action="would-build", reason=reason, plan=plan))
    else:
        work.append((planned, reason))


def _build_one(planned: Planned, reason: str, update: Callable[[str, str], None]) -> Outcome:
    from robocore.adapters.image_builder import build_image

    client = local_docker()
    start = time.monotonic()
    key = planned.plan.ref
    update(key, f"building ({reason})")
    try:
        image_id = build_image(client, planned.plan, planned.files, labels=planned.labels, native_arch=native_arch(),
                               output=lambda line: update(key, line))
    finally:
        client.close()
    return Outcome(what=key, role=planned.plan.role, action="built", reason=reason, image_id=image_id,
                   seconds=time.monotonic() - start)


def run_builds(report: Reporter, work: Sequence[tuple[Planned, str]], *, parallel: bool) -> list[Outcome]:
    """Build each queued image (side by side with ``parallel``); every one is tried, then the first
    error is raised (after reporting the images that were built)."""
    outcomes: list[Outcome] = []
    if not work:
        return outcomes
    errors: list[BaseException] = []
    with report.progress() as update:
        if not parallel:  # one after the other; the first failure stops the rest
            return [_build_one(planned, reason, update) for planned, reason in work]
        done = in_parallel(work, lambda item: _build_one(item[0], item[1], update), limit=MAX_PARALLEL,
                           name="robocore-image")
    for _, result in done:
        if isinstance(result, BaseException):
            errors.append(result)
        else:
            outcomes.append(result)
    if errors:
        report_outcomes(report, outcomes)
        first = errors[0]
        if len(errors) > 1 and isinstance(first, BuildError):
            raise BuildError(first.message + f"\n(and {len(errors) - 1} more image(s) failed)", hint=first.hint)
        raise first
    return outcomes
