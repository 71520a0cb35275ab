"""test: ``colcon test`` of each component's workspace inside its staged image, with a result per package.

The container is the one ``build`` uses: the component's staged image, run as the invoking
UID:GID, with the workspace and ``.robocore/build/<c>/{build,install,log}`` bind-mounted at the
same paths and the same environment. The tests run against the install tree of the last build,
so ``test`` first builds what is stale (as ``cargo test`` does), through ``build`` itself with its
own progress and results, so an edited test file is the one that runs; a failed build stops the
run before any test. With ``--no-build`` the build must already be current: a component that was
never built, or whose sources or image changed since its last build, is refused with the hint to
run ``build`` first.

colcon leaves JUnit XML in each package's build folder (``pytest.xml`` of ``ament_python``
packages, ``test_results/**.xml`` of ``ament_cmake`` ones). Those files are removed before the
run, so a package's results are this run's or none, then read (:mod:`robocore.plan.junit`) and
merged into ``.robocore/test-results/<component>/<package>.xml``; that folder holds the results of
the last run only. Any failed or errored test, unreadable result file or failed colcon run is a
:class:`~robocore.errors.TestFailure` (exit code 9) after every component was tried.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

from robocore.commands.build import plan_build, workspace_packages
from robocore.commands.support.colcon_output import colcon_listener
from robocore.commands.support.context import Options
from robocore.commands.support.hosts import in_parallel
from robocore.commands.support.machine import MAX_PARALLEL, check_emulation, local_docker, native_arch
from robocore.commands.support.reporting import Reporter
from robocore.commands.support.workspace import selected_components
from robocore.config.model import Component
from robocore.errors import BuildError, TestFailure, UnsafePath, UsageError
from robocore.files import make_folder, remove_file, remove_tree, write_atomic
from robocore.plan import arches, colcon, junit, naming
from robocore.project import Project

#: JUnit files colcon's test steps leave in a package's build folder, and folders searched for more.
RESULT_FILES = ("pytest.xml",)
RESULT_FOLDERS = ("test_results",)
#: A result file larger than this is reported, not read.
MAX_RESULT_BYTES = 64 * 1024 * 1024
#: Lines of colcon's own output shown when it fails.
OUTPUT_TAIL = 20


@dataclass(frozen=True)
class ComponentTests:
    """What ``test`` runs for one component."""

    component: Component
    image: str
    arch: str
    workspace: Path
    out: Path  # .robocore/build/<component>
    packages: tuple[str, ...]  # the packages tested, sorted
    select: tuple[str, ...] = ()  # --packages-select; empty: the whole workspace

    @property
    def argv(self) -> list[str]:
        """The colcon command line."""
        return colcon.workspace_test_argv(self.select)

    @property
    def mounts(self) -> dict[str, str]:
        """``{host path: container path}``, the same as the component's build."""
        return colcon.workspace_mounts(self.workspace, self.out)


@dataclass
class ComponentOutcome:
    """How one component's test run ended: colcon's exit code and each package's results."""

    component: str
    exit_code: int
    packages: list[junit.PackageResults] = field(default_factory=list)
    output: list[str] = field(default_factory=list)  # colcon's last lines when it failed
    result_files: dict[str, str] = field(default_factory=dict)  # package -> project-relative merged file

    @property
    def ok(self) -> bool:
        """colcon ran and every package passed."""
        return self.exit_code == 0 and all(p.ok for p in self.packages)


def plan_tests(project: Project, components: Sequence[Component], select: Sequence[str]) -> list[ComponentTests]:
    """One plan per component with a package to test; every name in ``select`` must be a package of them.

    Without ``select`` every component with a workspace is tested, whole.
    """
    found: dict[str, tuple[str, ...]] = {}
    for comp in components:
        assert comp.folder is not None
        roots, _ = workspace_packages(project.root / comp.folder)
        found[comp.name] = tuple(sorted(roots))
    known = sorted({p for names in found.values() for p in names})
    unknown = [name for name in dict.fromkeys(select) if name not in known]
    if unknown:
        where = f" of component {components[0].name}" if len(components) == 1 else ""
        raise UsageError(f"unknown package{'s' if len(unknown) > 1 else ''} "
                         f"{', '.join(repr(n) for n in unknown)}{where} (known: {', '.join(known) or 'none'})")
    plans = []
    for comp in components:
        packages = found[comp.name]
        chosen = tuple(p for p in packages if p in select) if select else packages
        if not chosen:
            continue
        plans.append(ComponentTests(
            component=comp, image=f"{naming.component_image(project.robot, project.name, comp.name)}:latest",
            arch=project.robot.host(comp.runs_on).arch.value, workspace=project.root / str(comp.folder),
            out=project.build_dir(comp.name), packages=chosen,
            select=chosen if select and chosen != packages else ()))
    return plans


def _built_here(project: Project, comps: Sequence[Component], report: Reporter, *, named: bool) -> list[Component]:
    """``comps`` without those built on their hosts (``builds_here``), whose build folder is there, not here:
    one line each, a UsageError when the component was named."""
    from robocore.plan.remote_build import builds_on_host

    kept = []
    for comp in comps:
        host = project.robot.host(comp.runs_on)
        if not builds_on_host(host):
            kept.append(comp)
            continue
        why = (f"component {comp.name} is built on host {host.name} (builds_here: true), so its build folder, which "
               "colcon test needs, is there and not on this machine")
        if named:
            raise UsageError(why, hint=f"set builds_here: false on host {host.name} to build and test it here")
        report.notice(f"{why}: not tested")
    return kept


def _rel(project: Project, path: Path) -> str:
    try:
        return path.relative_to(project.root).as_posix()
    except ValueError:
        return str(path)


def _not_built(project: Project, plan: ComponentTests) -> BuildError:
    return BuildError(f"component {plan.component.name}: not built yet "
                      f"(no {_rel(project, plan.out / 'install')}); the tests run against the build's install tree",
                      hint=f"run `robocore build --component {plan.component.name}` first (or `invoke build test`)")


def check_current(project: Project, plan: ComponentTests, image_id: str) -> None:
    """Raise BuildError unless the last build of the component is of its current sources and image."""
    if not (plan.out / "install").is_dir():
        raise _not_built(project, plan)
    built = plan_build(project, plan.component, image_id)
    if built.changed == []:
        return
    if built.changed is None and built.reason == "first build":
        raise _not_built(project, plan)
    why = built.reason if built.changed is None else f"changed: {', '.join(built.changed)}"
    raise BuildError(f"component {plan.component.name}: the build is out of date ({why}); "
                     "the tests would run the old code",
                     hint=f"run `robocore build --component {plan.component.name}` first (or `invoke build test`)")


# ---------------------------------------------------------------------------------------------- results


def result_files(package_build: Path) -> list[Path]:
    """The JUnit files colcon's test steps left in one package's build folder (regular files, no symlinks)."""
    found = [package_build / name for name in RESULT_FILES]
    for folder in RESULT_FOLDERS:
        if not (package_build / folder).is_symlink():
            found += sorted((package_build / folder).rglob("*.xml"))
    return [p for p in found if p.is_file() and not p.is_symlink()]


def clear_results(plan: ComponentTests) -> None:
    """Remove the result files of the packages about to be tested, so stale ones are never counted."""
    for package in plan.packages:
        build = plan.out / "build" / package
        # colcon (in a container) wrote this tree: a link in it is left alone, never followed
        for name in RESULT_FILES:
            with contextlib.suppress(UnsafePath):
                remove_file(build / name)
        for folder in RESULT_FOLDERS:
            with contextlib.suppress(UnsafePath):
                remove_tree(build / folder)


def read_results(project: Project, plan: ComponentTests, outcome: ComponentOutcome,
                 failed: Sequence[str]) -> None:
    """Read each tested package's result files into ``outcome`` and write its merged file under
    ``.robocore/test-results/<component>/``. ``failed``: packages colcon reported as failed."""
    folder = project.test_results_dir / plan.component.name
    for package in plan.packages:
        files: list[tuple[str, bytes]] = []
        too_large: list[str] = []
        for path in result_files(plan.out / "build" / package):
            if path.stat().st_size > MAX_RESULT_BYTES:
                too_large.append(f"{_rel(project, path)}: larger than {MAX_RESULT_BYTES // 2**20} MiB, not read")
                continue
            files.append((_rel(project, path), path.read_bytes()))
        results = junit.package_results(package, files)
        extra = tuple(too_large)
        if package in failed and results.ok:
            log = _rel(project, plan.out / "log" / "latest_test" / package)
            extra += (f"colcon test failed for {package} (log: {log})",)
        if extra:
            results = dataclasses.replace(results, problems=results.problems + extra)
        target = folder / f"{package}.xml"
        write_atomic(target, junit.merged(results, files))
        outcome.packages.append(results)
        outcome.result_files[package] = _rel(project, target)


# ---------------------------------------------------------------------------------------------- running


def _run(project: Project, plan: ComponentTests, report: Reporter,
         update: Callable[[str, str], None]) -> ComponentOutcome:
    """colcon test of one component in a throw-away container of its staged image."""
    from robocore.adapters.image_builder import run_streaming

    name = plan.component.name
    for sub in ("build", "install", "log"):
        make_folder(plan.out / sub, shared=sub == "install")  # as build makes them: the install tree is sent to hosts
    clear_results(plan)
    events: list[colcon.PackageEvent] = []
    other: list[str] = []

    on_line = colcon_listener(name, "testing", "tests", events, other, update, report)
    update(name, "colcon test")
    client = local_docker()
    try:
        code = run_streaming(
            client, plan.image, plan.argv, user=f"{os.getuid()}:{os.getgid()}", volumes=plan.mounts,
            environment=colcon.CONTAINER_ENV,
            labels={naming.LABEL_PROJECT: project.name, naming.LABEL_COMPONENT: name, naming.LABEL_ROLE: "test"},
            platform=arches.platform(plan.arch) if plan.arch != native_arch() else None, on_line=on_line,
        )
    finally:
        client.close()
    outcome = ComponentOutcome(component=name, exit_code=code, output=other[-OUTPUT_TAIL:] if code else [])
    failed = [e.package for e in events if e.state in ("failed", "aborted")]
    read_results(project, plan, outcome, failed)
    return outcome


def _run_all(project: Project, plans: Sequence[ComponentTests], report: Reporter) -> list[ComponentOutcome]:
    """Every component's tests, side by side (one container each); an exception is raised after all ran."""
    with report.progress() as update:
        done = in_parallel(plans, lambda plan: _run(project, plan, report, update), limit=MAX_PARALLEL,
                           name="robocore-test")
    errors = [result for _, result in done if isinstance(result, BaseException)]
    if errors:
        raise errors[0]
    return [result for _, result in done if not isinstance(result, BaseException)]


def test(options: Options, *, component: str | None, packages: Sequence[str] = (), build_first: bool = True) -> None:
    """Run each component's package tests; print a result per package; fail when any test did not pass.

    With ``build_first`` the components are built first where stale (``robocore build``), so the tests run
    the current sources; without it a stale build is refused."""
    project = options.load()
    report = options.report
    comps = [c for c in selected_components(project, component) if c.folder is not None]
    if component and not comps:
        raise UsageError(f"component {component!r} has no folder: nothing to test")
    comps = _built_here(project, comps, report, named=component is not None)
    plans = plan_tests(project, comps, packages)
    if build_first and plans:
        from robocore.commands.build import build

        # the build reports as itself: its own table for people; with --json its results stay out of the test's
        # one document (which keeps the build's warnings)
        building = dataclasses.replace(options, task="build")
        build(building, component=component)
        report.problems.extend(building.report.problems)
    if options.dry_run:
        show_plan(project, plans, report)
        return
    if not plans:
        raise UsageError("no component has a workspace with packages: nothing to test")
    from robocore.adapters.image_builder import image_state

    client = local_docker()
    try:
        for plan in plans:
            state = image_state(client, plan.image)
            if state is None:
                raise BuildError(f"component {plan.component.name}: no staged image {plan.image}",
                                 hint="run `robocore stage` first")
            check_emulation(plan.arch, native_arch(), f"component {plan.component.name}")
            check_current(project, plan, state.id)
    finally:
        client.close()
    remove_tree(project.test_results_dir, ignore_errors=True)
    outcomes = _run_all(project, plans, report)
    report.add(*results(outcomes))
    if report.human:
        print_report(project, outcomes, report)
    error = failure(project, outcomes, details=not report.human and not options.json)
    if error is not None:
        raise error


@dataclass(frozen=True)
class PlannedTests:
    """What ``test`` would run for one component (a dry run)."""

    kind: ClassVar[str] = "test_plan"
    component: str
    image: str
    user: str
    packages: list[str]
    mounts: dict[str, str]
    argv: list[str]
    built: bool


def show_plan(project: Project, plans: Sequence[ComponentTests], report: Reporter) -> None:
    """The dry run: per component, the image, mounts and colcon command line; Docker is not contacted."""
    import shlex

    uid, gid = os.getuid(), os.getgid()
    for plan in plans:
        built = (plan.out / "install").is_dir()
        report.add(PlannedTests(component=plan.component.name, image=plan.image, user=f"{uid}:{gid}",
                                packages=list(plan.packages), mounts=plan.mounts, argv=plan.argv, built=built))
        note = "" if built else " (not built yet: run build first)"
        report.plain(f"# {plan.component.name}: {', '.join(plan.packages)} in {plan.image} as {uid}:{gid}{note}")
        for host, inside in plan.mounts.items():
            report.plain(f"  mount {host} -> {inside}")
        report.plain(f"  {shlex.join(plan.argv)}")
        report.plain(f"  results: {_rel(project, project.test_results_dir / plan.component.name)}/<package>.xml")
    if not plans:
        report.plain("# nothing to test: no component has a workspace with packages")


# ---------------------------------------------------------------------------------------------- report


def print_report(project: Project, outcomes: Sequence[ComponentOutcome], report: Reporter | None = None) -> None:
    """The table of packages, then each test that did not pass with the first lines of its message."""
    from rich.markup import escape
    from rich.table import Table

    report = report or Reporter()
    table = Table(title="package tests", title_justify="left")
    for column in ("component", "package", "tests", "failures", "errors", "skipped", "result"):
        table.add_column(column, justify="right" if column in ("tests", "failures", "errors", "skipped") else "left")
    for outcome in outcomes:
        for p in outcome.packages:
            verdict = "[green]passed[/]" if p.ok else "[red]FAILED[/]"
            table.add_row(escape(outcome.component), escape(p.package), str(p.tests), str(p.failures),
                          str(p.errors), str(p.skipped), verdict)
    report.table(table)
    for outcome in outcomes:
        for p in outcome.packages:
            for case in p.not_passed:
                report.out(f"{'FAILED' if case.outcome == 'failed' else 'ERROR'} {p.package}: {case.test_id}")
                for line in case.message.splitlines():
                    report.out(f"    {line}")
            for problem in p.problems:
                report.out(f"ERROR {p.package}: {problem}")
        if outcome.exit_code:
            report.out(f"{outcome.component}: colcon test exited {outcome.exit_code}")
            for line in outcome.output:
                report.out(f"    {line}")
    report.out(f"JUnit XML: {_rel(project, project.test_results_dir)}/<component>/<package>.xml")


@dataclass(frozen=True)
class FailedTest:
    """A test that failed or errored, with its message."""

    test: str
    outcome: str
    message: str


@dataclass(frozen=True)
class PackageTests:
    """One package's test results (``result_file``: its merged JUnit XML, project-relative)."""

    package: str
    ok: bool
    tests: int
    failures: int
    errors: int
    skipped: int
    result_file: str | None
    problems: list[str]
    failed: list[FailedTest]


@dataclass(frozen=True)
class ComponentTestResults:
    """One component's test run: colcon's exit code (and last lines when it failed) and each package."""

    kind: ClassVar[str] = "tests"
    component: str
    ok: bool
    colcon_exit_code: int
    colcon_output: list[str]
    packages: list[PackageTests]


def results(outcomes: Sequence[ComponentOutcome]) -> list[ComponentTestResults]:
    """The typed results of a test run, one per component."""
    return [ComponentTestResults(
        component=o.component, ok=o.ok, colcon_exit_code=o.exit_code, colcon_output=list(o.output),
        packages=[PackageTests(
            package=p.package, ok=p.ok, tests=p.tests, failures=p.failures, errors=p.errors, skipped=p.skipped,
            result_file=o.result_files.get(p.package), problems=list(p.problems),
            failed=[FailedTest(c.test_id, c.outcome, c.message) for c in p.not_passed],
        ) for p in o.packages],
    ) for o in outcomes]


def failure(project: Project, outcomes: Sequence[ComponentOutcome], *, details: bool) -> TestFailure | None:
    """The error of a run where something did not pass (None when all passed). Its first line counts what
    failed; with ``details`` (no report printed) one more line names each test that did not pass."""
    bad = [(o, p) for o in outcomes for p in o.packages if not p.ok]
    broken = [o for o in outcomes if o.exit_code]
    if not bad and not broken:
        return None
    parts = []
    if bad:
        failures = sum(p.failures for _, p in bad)
        errors = sum(p.errors for _, p in bad)
        parts.append(f"{failures} failed, {errors} errored in {', '.join(p.package for _, p in bad)}")
    parts += [f"colcon test exited {o.exit_code} in component {o.component}" for o in broken]
    lines = ["tests did not pass: " + "; ".join(parts)
             + f" (JUnit XML in {_rel(project, project.test_results_dir)}/)"]
    if details:
        for _, p in bad:
            lines += [f"{p.package}: {c.outcome} {c.test_id}: {(c.message.splitlines() or [''])[0]}"
                      for c in p.not_passed]
            lines += [f"{p.package}: {problem}" for problem in p.problems]
    return TestFailure("\n".join(lines))
