"""The records in ``.robocore/``: where they are (the project folder says), and what reading them gives."""

from __future__ import annotations

from pathlib import Path

from robocore.commands.support import state
from robocore.config.model import Robot
from robocore.plan.containers import host_specs
from robocore.project import Project, ProjectFolder


def _project(root: Path) -> Project:
    robot = Robot.model_validate({
        "ros_distro": "jazzy",
        "hosts": [{"name": "main", "ip": "10.0.0.5"}, {"name": "dev", "ip": "127.0.0.1"}],
        "components": [{"name": "a", "runs_on": "main", "folder": "a"}, {"name": "b", "runs_on": "dev", "folder": "b"}],
    })
    return Project(root=root, robot=robot)


def test_every_record_is_under_the_state_folder(tmp_path: Path) -> None:
    folder = ProjectFolder(tmp_path)
    paths = [folder.build_state_file("a"), folder.sync_state_file("main"), folder.history_file("main"),
             folder.compose_file("main"), folder.dds_dir, folder.cache_dir, folder.ssh_hosts_record,
             folder.test_results_dir, folder.test_runs_dir, folder.build_lock, folder.schema_file,
             folder.shell_dir, folder.home_dir("me"), folder.x11_dir("c"), folder.sync_links_dir("main", "a")]
    assert all(p.is_relative_to(tmp_path / ".robocore") for p in paths)
    assert len(set(paths)) == len(paths)


def test_missing_or_broken_records_read_as_empty(tmp_path: Path) -> None:
    project = _project(tmp_path)
    assert state.read_synced(project, "main") == {} and state.history(project, "main") == []
    for path in (project.sync_state_file("main"), project.history_file("main")):
        path.parent.mkdir(parents=True)
        path.write_text("{not json")
    assert state.read_synced(project, "main") == {} and state.history(project, "main") == []
    project.history_file("main").write_text('{"runs": {"not": "a list"}}')
    assert state.history(project, "main") == []


def test_the_history_keeps_the_last_runs_and_skips_repeats(tmp_path: Path) -> None:
    project = _project(tmp_path)
    main = project.host("main")
    state.write_synced(project, "main", {"a": {"release": "r1", "digest": "d"}})
    for number in range(state.HISTORY_KEEP + 5):
        state.record_run(project, main, f"v{number}")
        state.record_run(project, main, f"v{number}")  # the same again: not a new entry
    runs = state.history(project, "main")
    assert len(runs) == state.HISTORY_KEEP
    assert runs[-1]["tag"] == f"v{state.HISTORY_KEEP + 4}" and runs[-1]["releases"] == {"a": "r1"}


def test_labels_follow_the_release_and_the_build(tmp_path: Path) -> None:
    project = _project(tmp_path)
    main, dev = project.host("main"), project.host("dev")
    assert state.with_synced_release(project, main, host_specs(project, "main")) == host_specs(project, "main")
    state.write_synced(project, "main", {"a": {"release": "r2", "digest": "d"}})
    [spec] = [s for s in state.with_synced_release(project, main, host_specs(project, "main")) if s.service == "a"]
    assert (state.LABEL_RELEASE, "r2") in spec.extra_labels
    before = state.with_local_build(project, dev, host_specs(project, "dev"))
    state.write_build_state(project.build_state_file("b"), {"packages": {"p": "h"}})
    after = state.with_local_build(project, dev, host_specs(project, "dev"))
    [label] = [v for s in after if s.service == "b" for k, v in s.extra_labels if k == state.LABEL_BUILD]
    assert before != after and label
    assert state.with_local_build(project, main, host_specs(project, "main")) == host_specs(project, "main")
