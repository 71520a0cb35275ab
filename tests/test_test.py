"""The test task without Docker: colcon's argv and mounts, package selection, the build-is-current check,
reading and writing results, the report, and the whole command over a fake colcon container."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pytest
from fakes import FakeDocker

from robocore.commands import build
from robocore.commands import test as test_command
from robocore.commands.support.context import Options
from robocore.errors import BuildError, TestFailure, UsageError
from robocore.plan import colcon, junit
from robocore.project import Project

ROBOT = """\
ros_distro: jazzy
base: {kind: wheels}
hosts:
  - {name: dev, ip: 127.0.0.1, user: me}
components:
  - {name: talker, folder: ws/talker, runs_on: dev}
  - {name: listener, folder: ws/listener, runs_on: dev}
  - {name: camera, image: "vendor/camera:1", runs_on: dev}
"""
PACKAGES = {"talker": ("demo_talker", "talker_msgs"), "listener": ("demo_listener",)}

PASS = b"""<testsuites><testsuite name="pytest" tests="2">
<testcase classname="{pkg}.test.test_a" name="test_one"/><testcase classname="{pkg}.test.test_a" name="test_two"/>
</testsuite></testsuites>"""
FAIL = b"""<testsuite name="pytest" tests="2"><testcase classname="{pkg}.test.test_a" name="test_one"/>
<testcase classname="{pkg}.test.test_a" name="test_wrong">
<failure message="AssertionError: assert 'hello from talker #1' == 'wrong'&#10;  - wrong">trace</failure>
</testcase></testsuite>"""


def _project(root: Path) -> Project:
    for comp, packages in PACKAGES.items():
        for pkg in packages:
            folder = root / "ws" / comp / "src" / pkg
            (folder / "test").mkdir(parents=True)
            (folder / "package.xml").write_text(f"<package><name>{pkg}</name></package>")
            (folder / "test" / "test_a.py").write_text("def test_one():\n    pass\n")
    (root / "robot.yaml").write_text(ROBOT)
    return Project.load(root)


@pytest.fixture
def project(tmp_path: Path) -> Project:
    return _project(tmp_path / "robot")


def _plans(project: Project, select: Sequence[str] = (), component: str | None = None) -> dict[str, Any]:
    comps = [project.robot.component(component)] if component else \
        [c for c in project.robot.components if c.folder is not None]
    return {p.component.name: p for p in test_command.plan_tests(project, comps, select)}


# ------------------------------------------------------------------------------------------- argv and mounts


def test_colcon_test_argv_uses_the_folders_of_the_build() -> None:
    argv = colcon.workspace_test_argv()
    assert argv == ["colcon", "--log-base", "/robocore/log", "test", "--base-paths", "/robocore/ws",
                    "--build-base", "/robocore/build", "--install-base", "/robocore/install",
                    "--event-handlers", "console_start_end+", "console_direct-"]
    built = colcon.workspace_build_argv()
    assert argv[argv.index("--base-paths"):argv.index("--event-handlers")] == \
        built[built.index("--base-paths"):built.index("--event-handlers")]
    assert "--return-code-on-test-failure" not in argv  # the results say whether tests passed
    assert colcon.workspace_test_argv(["a", "b_c"])[-5:] == [
        "--packages-select", "a", "b_c", "--event-handlers", "console_start_end+", "console_direct-"][-5:]
    assert colcon.workspace_test_argv(["a"])[10:12] == ["--packages-select", "a"]


@pytest.mark.parametrize("name", ["--packages-ignore", "-x", "", "a b", "a;b"])
def test_a_package_name_never_becomes_an_option(name: str) -> None:
    with pytest.raises(UsageError, match="not a package name"):
        colcon.workspace_test_argv(["ok", name])


def test_mounts_are_the_workspace_and_the_build_output(tmp_path: Path) -> None:
    assert colcon.workspace_mounts(tmp_path / "ws", tmp_path / "out") == {
        str(tmp_path / "ws"): "/robocore/ws", str(tmp_path / "out/build"): "/robocore/build",
        str(tmp_path / "out/install"): "/robocore/install", str(tmp_path / "out/log"): "/robocore/log"}


# ------------------------------------------------------------------------------------------- selection


def test_every_workspace_component_is_tested_whole(project: Project) -> None:
    plans = _plans(project)
    assert sorted(plans) == ["listener", "talker"]  # camera has a pre-built image: nothing to test
    assert plans["talker"].packages == ("demo_talker", "talker_msgs")
    assert plans["talker"].select == ()
    assert "--packages-select" not in plans["talker"].argv
    assert plans["talker"].image == "robot-talker:latest"
    assert plans["talker"].mounts[str(project.root / "ws/talker")] == "/robocore/ws"
    assert plans["talker"].mounts[str(project.build_dir("talker") / "install")] == "/robocore/install"


def test_packages_select_keeps_only_the_components_that_hold_them(project: Project) -> None:
    plans = _plans(project, ["demo_listener"])
    assert list(plans) == ["listener"]
    assert plans["listener"].packages == ("demo_listener",)
    assert plans["listener"].select == ()  # the whole workspace: no --packages-select needed
    plans = _plans(project, ["talker_msgs", "demo_listener"])
    assert plans["talker"].packages == ("talker_msgs",)
    assert plans["talker"].argv[10:12] == ["--packages-select", "talker_msgs"]


def test_unknown_packages_are_one_usage_error(project: Project) -> None:
    with pytest.raises(UsageError) as caught:
        _plans(project, ["demo_talker", "nope", "nada"])
    assert caught.value.message == ("unknown packages 'nope', 'nada' "
                                    "(known: demo_listener, demo_talker, talker_msgs)")
    assert caught.value.exit_code == 2
    with pytest.raises(UsageError, match=r"unknown package 'demo_talker' of component listener \(known: demo_l"):
        _plans(project, ["demo_talker"], component="listener")


# ------------------------------------------------------------------------------------------- build current


def _record_build(project: Project, image_id: str = "img1") -> None:
    for comp in ("talker", "listener"):
        plan = build.plan_build(project, project.robot.component(comp), image_id)
        (plan.out / "install").mkdir(parents=True, exist_ok=True)
        build.record_build(plan)


def test_the_tests_need_a_current_build(project: Project) -> None:
    plan = _plans(project)["talker"]
    with pytest.raises(BuildError, match=r"component talker: not built yet \(no .robocore/build/talker/install\)") \
            as caught:
        test_command.check_current(project, plan, "img1")
    assert caught.value.hint is not None and "robocore build --component talker" in caught.value.hint
    _record_build(project)
    test_command.check_current(project, plan, "img1")  # current: no error
    with pytest.raises(BuildError, match=r"out of date \(image changed\)"):
        test_command.check_current(project, plan, "img2")
    (project.root / "ws/talker/src/talker_msgs/test/test_a.py").write_text("def test_one():\n    assert False\n")
    with pytest.raises(BuildError, match=r"out of date \(changed: talker_msgs\); the tests would run the old code"):
        test_command.check_current(project, plan, "img1")
    test_command.check_current(project, _plans(project)["listener"], "img1")  # the other one is still current


# ------------------------------------------------------------------------------------------- results


def _write_result(project: Project, comp: str, pkg: str, data: bytes, name: str = "pytest.xml") -> Path:
    path = project.build_dir(comp) / "build" / pkg / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(data.replace(b"{pkg}", pkg.encode()))
    return path


def test_results_are_read_merged_and_written_per_package(project: Project) -> None:
    plan = _plans(project)["talker"]
    _write_result(project, "talker", "demo_talker", FAIL)
    _write_result(project, "talker", "talker_msgs", PASS, "test_results/talker_msgs/a.xunit.xml")
    _write_result(project, "talker", "talker_msgs", b"<testsuite><oops", "test_results/talker_msgs/b.xml")
    outcome = test_command.ComponentOutcome(component="talker", exit_code=0)
    test_command.read_results(project, plan, outcome, failed=[])
    talker, msgs = outcome.packages
    assert (talker.package, talker.tests, talker.failures, talker.errors) == ("demo_talker", 2, 1, 0)
    assert (msgs.package, msgs.tests, msgs.errors) == ("talker_msgs", 2, 1)
    assert msgs.problems[0].startswith(".robocore/build/talker/build/talker_msgs/test_results/talker_msgs/b.xml: "
                                       "not readable as XML")
    assert outcome.result_files == {"demo_talker": ".robocore/test-results/talker/demo_talker.xml",
                                    "talker_msgs": ".robocore/test-results/talker/talker_msgs.xml"}
    merged = ET.parse(project.root / outcome.result_files["demo_talker"]).getroot()
    assert merged.get("failures") == "1"
    assert merged.find("testsuite/testcase[@name='test_wrong']/failure") is not None
    assert not outcome.ok


def test_a_package_colcon_reports_failed_is_an_error_even_with_clean_results(project: Project) -> None:
    plan = _plans(project)["listener"]
    _write_result(project, "listener", "demo_listener", PASS)
    outcome = test_command.ComponentOutcome(component="listener", exit_code=1)
    test_command.read_results(project, plan, outcome, failed=["demo_listener"])
    [results] = outcome.packages
    assert results.problems == ("colcon test failed for demo_listener "
                                "(log: .robocore/build/listener/log/latest_test/demo_listener)",)
    assert not results.ok
    # negative control: the same results, not reported failed, pass
    outcome = test_command.ComponentOutcome(component="listener", exit_code=0)
    test_command.read_results(project, plan, outcome, failed=[])
    assert outcome.packages[0].ok and outcome.ok


def test_stale_results_are_removed_before_a_run_and_symlinks_never_followed(project: Project,
                                                                            tmp_path: Path) -> None:
    plan = _plans(project)["talker"]
    old = _write_result(project, "talker", "demo_talker", FAIL)
    nested = _write_result(project, "talker", "talker_msgs", FAIL, "test_results/talker_msgs/x.xml")
    keep = _write_result(project, "talker", "talker_msgs", b"colcon's own", "colcon_build.rc")
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "precious.xml").write_bytes(PASS)
    linked = project.build_dir("talker") / "build" / "demo_talker" / "test_results"
    linked.symlink_to(outside)
    assert test_command.result_files(linked.parent) == [old]
    test_command.clear_results(plan)
    assert not old.exists() and not nested.exists() and keep.exists()
    assert (outside / "precious.xml").exists()  # the link was not followed into
    (linked.parent / "pytest.xml").symlink_to(outside / "precious.xml")
    assert test_command.result_files(linked.parent / "missing") == []
    assert linked.parent / "pytest.xml" not in test_command.result_files(linked.parent)


# ------------------------------------------------------------------------------------------- report


def _outcomes(project: Project) -> list[test_command.ComponentOutcome]:
    good = junit.package_results("demo_listener", [("p.xml", PASS.replace(b"{pkg}", b"demo_listener"))])
    bad = junit.package_results("demo_talker", [("p.xml", FAIL.replace(b"{pkg}", b"demo_talker"))])
    return [test_command.ComponentOutcome("talker", 0, [bad], result_files={"demo_talker": "x.xml"}),
            test_command.ComponentOutcome("listener", 0, [good])]


def test_the_report_is_a_table_then_each_failing_test_with_its_message(project: Project,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    test_command.print_report(project, _outcomes(project))
    out = capsys.readouterr().out
    rows = [line.split() for line in out.splitlines() if "demo_" in line and "│" in line]
    assert [[cell for cell in row if cell != "│"] for row in rows] == [
        ["talker", "demo_talker", "2", "1", "0", "0", "FAILED"],
        ["listener", "demo_listener", "2", "0", "0", "0", "passed"]]
    assert "FAILED demo_talker: demo_talker.test.test_a::test_wrong\n" \
           "    AssertionError: assert 'hello from talker #1' == 'wrong'\n      - wrong\n" in out
    assert "demo_listener.test" not in out  # passing tests are not listed
    assert "JUnit XML: .robocore/test-results/<component>/<package>.xml" in out


def test_json_is_one_document(project: Project) -> None:
    doc = [dataclasses.asdict(r) for r in test_command.results(_outcomes(project))]
    assert [c["ok"] for c in doc] == [False, True]
    talker = doc[0]["packages"][0]
    assert talker == {"package": "demo_talker", "ok": False, "tests": 2, "failures": 1, "errors": 0, "skipped": 0,
                      "result_file": "x.xml", "problems": [], "failed": [
                          {"test": "demo_talker.test.test_a::test_wrong", "outcome": "failed",
                           "message": "AssertionError: assert 'hello from talker #1' == 'wrong'\n  - wrong"}]}
    json.dumps(doc)


def test_the_error_counts_what_failed_and_names_tests_only_without_a_report(project: Project) -> None:
    outcomes = _outcomes(project)
    error = test_command.failure(project, outcomes, details=False)
    assert isinstance(error, TestFailure) and error.exit_code == 9
    assert error.lines() == ["tests did not pass: 1 failed, 0 errored in demo_talker "
                             "(JUnit XML in .robocore/test-results/)"]
    detailed = test_command.failure(project, outcomes, details=True)
    assert detailed is not None and detailed.lines()[0].endswith(
        "\ndemo_talker: failed demo_talker.test.test_a::test_wrong: AssertionError: assert 'hello from talker #1' "
        "== 'wrong'")
    broken = [test_command.ComponentOutcome("listener", 2, [], output=["colcon: error: unrecognized"])]
    error = test_command.failure(project, broken, details=False)
    assert error is not None and "colcon test exited 2 in component listener" in error.message
    assert test_command.failure(project, outcomes[1:], details=True) is None  # all passed


# ------------------------------------------------------------------------------------------- the command


class FakeState:
    id = "img1"


def _fake_docker(monkeypatch: pytest.MonkeyPatch, project: Project, results: Mapping[str, bytes],
                 calls: list[dict[str, Any]], code: int = 0) -> None:
    """A colcon test container that writes ``results[package]`` as the package's pytest.xml."""
    from robocore.adapters import image_builder

    def run_streaming(client: object, image: str, command: Sequence[str], **kwargs: Any) -> int:
        calls.append({"image": image, "argv": list(command), **kwargs})
        build_dir = next(host for host, inside in kwargs["volumes"].items() if inside == colcon.CONTAINER_BUILD)
        selected = command[command.index("--packages-select") + 1:command.index("--event-handlers")] \
            if "--packages-select" in command else [p for p, data in results.items()]
        for pkg in selected:
            if pkg in results:
                kwargs["on_line"](f"Starting >>> {pkg}")
                path = Path(build_dir) / pkg / "pytest.xml"
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_bytes(results[pkg].replace(b"{pkg}", pkg.encode()))
                kwargs["on_line"](f"Finished <<< {pkg} [0.50s]")
        return code

    monkeypatch.setattr(image_builder, "run_streaming", run_streaming)
    monkeypatch.setattr(image_builder, "image_state", lambda client, ref: FakeState())
    monkeypatch.setattr(test_command, "local_docker", lambda: FakeDocker())


def test_the_command_runs_colcon_test_as_the_user_and_fails_on_a_failing_test(
        project: Project, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    _record_build(project)
    stale = project.state_dir / "test-results" / "gone" / "old.xml"
    stale.parent.mkdir(parents=True)
    stale.write_text("<testsuite/>")
    calls: list[dict[str, Any]] = []
    _fake_docker(monkeypatch, project, {"demo_talker": FAIL, "talker_msgs": PASS, "demo_listener": PASS}, calls)
    with pytest.raises(TestFailure, match=r"^tests did not pass: 1 failed, 0 errored in demo_talker \(JUnit"):
        test_command.test(Options(project_dir=project.root), component=None, build_first=False)
    assert sorted(c["image"] for c in calls) == ["robot-listener:latest", "robot-talker:latest"]
    assert {c["user"] for c in calls} == {f"{os.getuid()}:{os.getgid()}"}
    assert all(c["environment"] == colcon.CONTAINER_ENV and c["labels"]["dev.robocore.role"] == "test"
               for c in calls)
    out = capsys.readouterr().out
    assert "FAILED demo_talker: demo_talker.test.test_a::test_wrong" in out
    assert not stale.exists()  # the results folder holds the last run only
    written = sorted(p.relative_to(project.state_dir).as_posix()
                     for p in (project.state_dir / "test-results").rglob("*.xml"))
    assert written == ["test-results/listener/demo_listener.xml", "test-results/talker/demo_talker.xml",
                       "test-results/talker/talker_msgs.xml"]


def test_the_command_passes_and_prints_json(project: Project, monkeypatch: pytest.MonkeyPatch,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    _record_build(project)
    calls: list[dict[str, Any]] = []
    _fake_docker(monkeypatch, project, {"demo_talker": PASS, "talker_msgs": PASS, "demo_listener": PASS}, calls)
    options = Options(project_dir=project.root, json=True, task="test")
    test_command.test(options, component="talker", packages=["talker_msgs"], build_first=False)
    options.report.finish()
    [call] = calls
    assert call["argv"][10:12] == ["--packages-select", "talker_msgs"]
    doc = json.loads(capsys.readouterr().out)
    assert doc["ok"] is True and doc["task"] == "test"
    assert [(p["package"], p["tests"]) for c in doc["results"] for p in c["packages"]] == [("talker_msgs", 2)]


def test_colcon_failing_to_run_is_a_test_failure(project: Project, monkeypatch: pytest.MonkeyPatch) -> None:
    _record_build(project)
    _fake_docker(monkeypatch, project, {}, [], code=2)
    with pytest.raises(TestFailure, match="colcon test exited 2 in component listener"):
        test_command.test(Options(project_dir=project.root, quiet=True), component="listener", build_first=False)


def test_a_stale_build_is_refused_before_any_container(project: Project, monkeypatch: pytest.MonkeyPatch) -> None:
    _record_build(project, image_id="older")
    calls: list[dict[str, Any]] = []
    _fake_docker(monkeypatch, project, {"demo_listener": PASS}, calls)
    with pytest.raises(BuildError, match="component listener: the build is out of date"):
        test_command.test(Options(project_dir=project.root), component="listener", build_first=False)
    assert calls == []


def test_dry_run_prints_the_plan_without_docker(project: Project, monkeypatch: pytest.MonkeyPatch,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    def no_docker() -> None:
        raise AssertionError("the dry run contacted Docker")

    monkeypatch.setattr(test_command, "local_docker", no_docker)
    test_command.test(Options(project_dir=project.root, dry_run=True), component=None, packages=["demo_talker"],
                       build_first=False)
    out = capsys.readouterr().out
    assert "# talker: demo_talker in robot-talker:latest as" in out and "(not built yet: run build first)" in out
    assert f"  mount {project.root / 'ws/talker'} -> /robocore/ws" in out
    assert "  colcon --log-base /robocore/log test --base-paths /robocore/ws" in out
    assert "--packages-select demo_talker" in out
    assert "listener" not in out
    assert not (project.state_dir / "test-results").exists()


def test_the_cli_repeats_packages_select_and_exits_2_on_an_unknown_package(project: Project) -> None:
    def robocore(*args: str) -> subprocess.CompletedProcess[str]:
        env = dict(os.environ)
        return subprocess.run([sys.executable, "-m", "robocore", "-p", str(project.root), "test", *args],
                              capture_output=True, text=True, timeout=60, env=env)

    ok = robocore("--dry-run", "--packages-select", "talker_msgs", "--packages-select", "demo_listener")
    assert ok.returncode == 0, ok.stderr
    assert "--packages-select talker_msgs --event-handlers" in ok.stdout and "# listener: demo_listener" in ok.stdout
    bad = robocore("--dry-run", "--packages-select", "nope")
    assert bad.returncode == 2
    assert bad.stderr == "error: unknown package 'nope' (known: demo_listener, demo_talker, talker_msgs)\n"
    assert bad.stdout == ""
    wrong = robocore("--component", "camera")
    assert wrong.returncode == 2 and "pre-built image vendor/camera:1" in wrong.stderr


def test_the_project_collection_has_the_task() -> None:
    from robocore.tasks import namespace

    assert "test" in namespace.task_names



def test_dry_run_json_is_one_document(project: Project, monkeypatch: pytest.MonkeyPatch,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(test_command, "local_docker", lambda: pytest.fail("the dry run contacted Docker"))
    options = Options(project_dir=project.root, dry_run=True, json=True, task="test")
    test_command.test(options, component="listener", build_first=False)
    options.report.finish()
    doc = json.loads(capsys.readouterr().out)
    [listener] = doc["results"]
    assert listener["kind"] == "test_plan"
    assert listener["argv"] == colcon.workspace_test_argv()
    assert listener["mounts"][str(project.root / "ws/listener")] == "/robocore/ws"
    assert (listener["packages"], listener["built"]) == (["demo_listener"], False)


# ---------------------------------------------------------------------------------------------- build first


def test_test_builds_the_selected_component_first_then_tests(project: Project, monkeypatch: pytest.MonkeyPatch) -> None:
    order: list[str] = []
    calls: list[dict[str, Any]] = []
    _fake_docker(monkeypatch, project, {"demo_listener": PASS}, calls)

    def fake_build(options: Options, *, component: str | None, full: bool = False) -> None:
        order.append(f"build {component}")
        _record_build(project)  # what a real build leaves: a current build record

    monkeypatch.setattr(build, "build", fake_build)
    test_command.test(Options(project_dir=project.root, quiet=True), component="listener")
    assert order == ["build listener"]
    assert [c["image"] for c in calls] == ["robot-listener:latest"]


def test_a_failed_build_first_runs_no_test(project: Project, monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[dict[str, Any]] = []
    _fake_docker(monkeypatch, project, {"demo_listener": PASS}, calls)

    def failing_build(options: Options, *, component: str | None, full: bool = False) -> None:
        raise BuildError("component listener: colcon build failed")

    monkeypatch.setattr(build, "build", failing_build)
    with pytest.raises(BuildError, match="colcon build failed"):
        test_command.test(Options(project_dir=project.root, quiet=True), component="listener")
    assert calls == []


def test_an_unknown_package_is_refused_before_building(project: Project, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(build, "build", lambda *a, **k: pytest.fail("built before the packages were checked"))
    with pytest.raises(UsageError, match="unknown package 'nope'"):
        test_command.test(Options(project_dir=project.root, quiet=True), component=None, packages=["nope"])


def test_dry_run_shows_the_build_that_would_come_first(project: Project, monkeypatch: pytest.MonkeyPatch,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(test_command, "local_docker", lambda: pytest.fail("the dry run contacted Docker"))
    test_command.test(Options(project_dir=project.root, dry_run=True), component="listener")
    out = capsys.readouterr().out
    assert out.index("# listener (first build) in") < out.index("# listener: demo_listener in")


def test_with_json_the_build_first_leaves_one_document_of_test_results(
        project: Project, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    calls: list[dict[str, Any]] = []
    _fake_docker(monkeypatch, project, {"demo_listener": PASS}, calls)

    def fake_build(options: Options, *, component: str | None, full: bool = False) -> None:
        from robocore.commands.support.reporting import Outcome

        options.report.add(Outcome(what="listener", role="build", action="up-to-date"))
        options.report.warn("a build warning")
        _record_build(project)

    monkeypatch.setattr(build, "build", fake_build)
    options = Options(project_dir=project.root, json=True, task="test")
    test_command.test(options, component="listener")
    options.report.finish()
    doc = json.loads(capsys.readouterr().out)
    assert doc["task"] == "test" and [r["kind"] for r in doc["results"]] == ["tests"]
    assert [p["message"] for p in doc["problems"]] == ["a build warning"]

