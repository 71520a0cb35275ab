"""The build fast path: edits that only change files colcon copies verbatim skip colcon."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from robocore.commands import build
from robocore.config.model import Robot
from robocore.plan.install_patch import Patch, is_build_description, plan_patches, verbatim_copies
from robocore.project import Project

SITE = "install/pkg_talker/lib/python3.11/site-packages"


# ------------------------------------------------------------------------------------------- pure


def test_a_copy_must_have_the_same_bytes_at_a_path_ending_with_the_source_path() -> None:
    sources = {"pkg_talker/node.py": ("d1", False), "pkg_talker/__init__.py": ("empty", False),
               "launch/__init__.py": ("empty", False), "setup.py": ("s", False)}
    outputs = {
        f"{SITE}/pkg_talker/node.py": "d1",
        "build/pkg_talker/build/lib/pkg_talker/node.py": "d1",
        f"{SITE}/pkg_talker/__init__.py": "empty",
        f"{SITE}/other/node.py": "d1",  # same bytes and name, wrong folder
        f"{SITE}/pkg_talker/old/node.py": "d0",  # wrong bytes
        "install/pkg_talker/share/setup.py": "s",  # build descriptions are never patched
        "install/pkg_other/lib/python3.11/site-packages/pkg_talker/node.py": "d1",  # another package's tree
    }
    copies = verbatim_copies("pkg_talker", sources, outputs)
    assert copies == {
        "pkg_talker/node.py": ["build/pkg_talker/build/lib/pkg_talker/node.py", f"{SITE}/pkg_talker/node.py"],
        "pkg_talker/__init__.py": [f"{SITE}/pkg_talker/__init__.py"],
    }


@pytest.mark.parametrize(("rel", "expected"), [
    ("package.xml", True), ("setup.py", True), ("sub/setup.cfg", True), ("CMakeLists.txt", True),
    ("cmake/Find.cmake", True), ("pkg/node.py", False), ("launch/a.launch.py", False),
])
def test_build_descriptions(rel: str, expected: bool) -> None:
    assert is_build_description(rel) is expected


BEFORE = {"pkg": {"pkg/node.py": ("a", False), "setup.py": ("s", False), "data/x.bin": ("x", False)}}
COPIES = {"pkg": {"pkg/node.py": ["install/pkg/lib/site-packages/pkg/node.py"]}}


def test_a_changed_copied_file_becomes_a_patch() -> None:
    now = {"pkg": {**BEFORE["pkg"], "pkg/node.py": ("b", False)}}
    patches, why = plan_patches(["pkg"], BEFORE, now, COPIES)
    assert why == ""
    assert patches == [Patch("pkg", "pkg/node.py", "b", "a", ("install/pkg/lib/site-packages/pkg/node.py",))]


@pytest.mark.parametrize(("change", "reason"), [
    ({"pkg/new.py": ("n", False)}, "file added: pkg/new.py"),
    ({"setup.py": ("s2", False)}, "setup.py describes the build"),
    ({"pkg/node.py": ("a", True)}, "pkg/node.py changed its executable bit"),
    ({"data/x.bin": ("y", False)}, "data/x.bin is not installed as a plain copy"),
])
def test_anything_colcon_might_do_differently_needs_colcon(change: dict[str, tuple[str, bool]], reason: str) -> None:
    now = {"pkg": {**BEFORE["pkg"], **change}}
    patches, why = plan_patches(["pkg"], BEFORE, now, COPIES)
    assert patches == [] and why == f"pkg: {reason}"


def test_a_removed_file_or_an_unknown_package_needs_colcon() -> None:
    now = {"pkg": {k: v for k, v in BEFORE["pkg"].items() if k != "data/x.bin"}}
    assert plan_patches(["pkg"], BEFORE, now, COPIES) == ([], "pkg: file removed")
    assert plan_patches(["new"], BEFORE, {"new": {}}, COPIES) == ([], "new: no file list from the last build")


# ------------------------------------------------------------------------------------------- I/O


def _project(root: Path) -> Project:
    pkg = root / "ws/talker/src/pkg_talker"
    (pkg / "pkg_talker").mkdir(parents=True)
    (pkg / "package.xml").write_text("<package><name>pkg_talker</name></package>")
    (pkg / "setup.py").write_text("from setuptools import setup\nsetup()\n")
    (pkg / "pkg_talker/__init__.py").write_text("")
    (pkg / "pkg_talker/node.py").write_text("GREETING = 'hello'\n")
    robot = Robot.model_validate({"ros_distro": "jazzy", "base": {"kind": "wheels"},
                                  "hosts": [{"name": "dev", "ip": "127.0.0.1"}],
                                  "components": [{"name": "talker", "runs_on": "dev", "folder": "ws/talker"}]})
    return Project(root=root, robot=robot)


def _fake_colcon(project: Project) -> Path:
    """What colcon leaves for an ament_python package: the modules copied into site-packages."""
    out = project.build_dir("talker")
    site = out / SITE / "pkg_talker"
    site.mkdir(parents=True)
    src = project.root / "ws/talker/src/pkg_talker/pkg_talker"
    for name in ("__init__.py", "node.py"):
        (site / name).write_bytes((src / name).read_bytes())
        (site / name).chmod(0o644)
    return site / "node.py"


def _built(tmp_path: Path) -> tuple[Project, Path, Path]:
    project = _project(tmp_path)
    comp = project.robot.component("talker")
    first = build.plan_build(project, comp, "img1")
    assert first.changed is None and first.reason == "first build"
    installed = _fake_colcon(project)
    build.record_build(first)
    return project, tmp_path / "ws/talker/src/pkg_talker/pkg_talker/node.py", installed


def test_an_edit_to_a_copied_module_is_written_into_the_install_tree(tmp_path: Path) -> None:
    project, source, installed = _built(tmp_path)
    comp = project.robot.component("talker")
    assert build.plan_build(project, comp, "img1").changed == []
    source.write_text("GREETING = 'edited'\n")
    plan = build.plan_build(project, comp, "img1")
    assert plan.changed == ["pkg_talker"] and "1 file copied, no colcon" in plan.reason
    outcome = build.apply_patches(plan)
    assert outcome is not None and outcome.action == "built" and outcome.packages == ["pkg_talker"]
    assert installed.read_text() == "GREETING = 'edited'\n"
    assert installed.stat().st_mode & 0o777 == 0o644
    assert build.plan_build(project, comp, "img1").changed == []  # the state now says it is built
    state = json.loads(project.build_state_file("talker").read_text())
    assert state["copies"]["pkg_talker"]["pkg_talker/node.py"] == [f"{SITE}/pkg_talker/node.py"]


def test_an_install_tree_changed_by_hand_is_left_to_colcon(tmp_path: Path) -> None:
    project, source, installed = _built(tmp_path)
    comp = project.robot.component("talker")
    installed.write_text("changed by someone\n")
    source.write_text("GREETING = 'edited'\n")
    plan = build.plan_build(project, comp, "img1")
    assert plan.patches
    assert build.apply_patches(plan) is None
    assert installed.read_text() == "changed by someone\n"  # nothing written


def test_new_files_a_new_image_and_full_builds_run_colcon(tmp_path: Path) -> None:
    project, source, _ = _built(tmp_path)
    comp = project.robot.component("talker")
    source.write_text("GREETING = 'edited'\n")
    assert build.plan_build(project, comp, "img1", full=True).patches == ()
    assert build.plan_build(project, comp, "img2").changed is None  # another image: everything
    (source.parent / "extra.py").write_text("X = 1\n")
    plan = build.plan_build(project, comp, "img1")
    assert plan.patches == () and plan.changed == ["pkg_talker"]
    assert "colcon: pkg_talker: file added: pkg_talker/extra.py" in plan.reason


def test_a_state_file_from_an_older_robocore_means_colcon(tmp_path: Path) -> None:
    project, source, _ = _built(tmp_path)
    state = project.build_state_file("talker")
    data = json.loads(state.read_text())
    state.write_text(json.dumps({"image": data["image"], "packages": data["packages"]}))
    source.write_text("GREETING = 'edited'\n")
    plan = build.plan_build(project, project.robot.component("talker"), "img1")
    assert plan.changed == ["pkg_talker"] and plan.patches == ()


def test_a_source_edited_again_after_planning_writes_nothing(tmp_path: Path) -> None:
    project, source, installed = _built(tmp_path)
    comp = project.robot.component("talker")
    init = source.parent / "__init__.py"
    installed_init = installed.parent / "__init__.py"
    source.write_text("GREETING = 'edited'\n")
    init.write_text("VERSION = 2\n")
    plan = build.plan_build(project, comp, "img1")
    assert len(plan.patches) == 2
    assert [p.source for p in plan.patches] == ["pkg_talker/__init__.py", "pkg_talker/node.py"]
    source.write_text("GREETING = 'again'\n")  # the second one, after planning, before applying
    assert build.apply_patches(plan) is None
    assert installed.read_text() == "GREETING = 'hello'\n" and installed_init.read_text() == ""
