"""What ``build`` believes colcon did: every package it asked for finished, and the packages it hashes are the
ones colcon builds (folders colcon ignores are left out)."""

from __future__ import annotations

from pathlib import Path

import pytest

from robocore.commands.build import workspace_packages
from robocore.plan.colcon import PackageEvent, parse_event, unbuilt


def _events(*lines: str) -> list[PackageEvent]:
    return [event for line in lines if (event := parse_event(line)) is not None]


def test_a_colcon_run_that_built_nothing_leaves_every_asked_package_unbuilt() -> None:
    # colcon without colcon-ros: a warning per package, no package event, exit 0
    events = _events("WARNING:colcon.colcon_core.verb:No task extension to 'build' a 'ros.ament_python' package",
                     "Summary: 0 packages finished [0.31s]")
    assert events == []
    assert unbuilt({"demo_talker": "h1", "talker_msgs": "h2"}, None, events) == ["demo_talker", "talker_msgs"]


def test_a_package_that_finished_is_built_and_one_only_started_is_not() -> None:
    events = _events("Starting >>> talker_msgs", "Finished <<< talker_msgs [1.20s]", "Starting >>> demo_talker")
    assert unbuilt({"demo_talker": "h1", "talker_msgs": "h2"}, None, events) == ["demo_talker"]


@pytest.mark.parametrize(("changed", "expected"), [([], []), (["demo_talker"], ["demo_talker"]),
                                                   (["talker_msgs"], [])])
def test_only_the_packages_asked_for_must_finish(changed: list[str], expected: list[str]) -> None:
    events = _events("Starting >>> talker_msgs", "Finished <<< talker_msgs [1.20s]")
    assert unbuilt({"demo_talker": "h1", "talker_msgs": "h2"}, changed, events) == expected


@pytest.mark.parametrize("marker", ["COLCON_IGNORE", "AMENT_IGNORE", "CATKIN_IGNORE"])
def test_a_package_in_a_folder_colcon_ignores_is_not_a_package_of_the_build(tmp_path: Path, marker: str) -> None:
    for name in ("kept", "ignored"):
        package = tmp_path / "src" / name
        package.mkdir(parents=True)
        (package / "package.xml").write_text(f"<package><name>{name}</name></package>")
    (tmp_path / "src" / "ignored" / marker).touch()
    roots, files = workspace_packages(tmp_path)
    assert roots == {"kept": "src/kept"} and set(files) == {"kept"}


def test_a_build_that_finished_nothing_it_was_asked_for_is_one_build_error_naming_the_packages() -> None:
    from robocore.errors import BuildError
    from robocore.plan.colcon import refuse_unbuilt

    warning = "WARNING:colcon.colcon_core.verb:No task extension to 'build' a 'ros.ament_python' package"
    with pytest.raises(BuildError, match=r"^component talker: colcon build on host pi exited 0 without building "
                                         r"demo_talker\n  WARNING:colcon") as caught:
        refuse_unbuilt("talker", {"demo_talker": "h1"}, None, [], [warning], where=" on host pi")
    assert "colcon-ros" in (caught.value.hint or "")
    refuse_unbuilt("talker", {"demo_talker": "h1"}, None, _events("Finished <<< demo_talker [1.0s]"), [])
