"""Loading a project opens the robot hosts' ssh connections early, only when a remote step follows; the
next command opens the recorded ones before loading anything."""

from __future__ import annotations

from pathlib import Path

import pytest

from robocore.adapters import docker_hosts, ssh
from robocore.commands.support import context, hosts, warmup
from robocore.config.model import Host, Robot
from robocore.project import Project, ProjectFolder


def _project(root: Path) -> Project:
    robot = Robot.model_validate({
        "ros_distro": "jazzy",
        "hosts": [{"name": "main", "ip": "10.0.0.5"}, {"name": "dev", "ip": "127.0.0.1"},
                  {"name": "spare", "ip": "10.0.0.9"},
                  {"name": "tls", "ip": "10.0.0.7", "docker": "tls",
                   "tls": {"ca_cert": "a", "client_cert": "b", "client_key": "c"}}],
        "components": [{"name": "a", "runs_on": "main", "image": "busybox"},
                       {"name": "b", "runs_on": "dev", "image": "busybox"},
                       {"name": "c", "runs_on": "tls", "image": "busybox"}],
    })
    return Project(root=root, robot=robot)


@pytest.mark.parametrize(("argv", "warmed", "fetched"), [
    # ssh hosts that run something (not spare); run's Docker connections are opened too
    (["build", "--component", "a", "sync", "run"], ["main"], ["main"]),
    (["-p", "x", "status"], ["main"], []),  # status connects with settings of its own
    (["down"], ["main"], ["main"]),
    (["build"], [], []),  # nothing remote follows
    (["sync", "--dry-run"], [], []),  # a dry run contacts nobody
    (["run", "--dry-run"], [], []),
])
def test_ssh_hosts_are_warmed_only_before_remote_steps(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                       argv: list[str], warmed: list[str], fetched: list[str]) -> None:
    seen: list[str] = []
    prefetched: list[tuple[str, int, int]] = []
    monkeypatch.setattr(ssh, "warm", lambda host: seen.append(host.name))
    monkeypatch.setattr(warmup, "WARMED", set())
    monkeypatch.setattr(docker_hosts, "prefetch", lambda host, timeout, *, connect_timeout: prefetched.append(
        (host.name, timeout, connect_timeout)))
    (tmp_path / "robot.yaml").write_text("# the project's file\n")
    project = _project(tmp_path)
    context.warm_remote_hosts(project, argv)
    context.warm_remote_hosts(project, argv)  # warmed once per process
    assert seen == warmed
    # (tls and local hosts are passed too: prefetch leaves all but ssh alone)
    assert sorted({name for name, _, _ in prefetched}) == (["dev", "main", "tls"] if fetched else [])
    assert all((t, c) == (hosts.CONNECT_API_TIMEOUT, hosts.HOST_CONNECT_TIMEOUT) for _, t, c in prefetched)


def test_the_next_command_warms_the_recorded_hosts_first_until_robot_yaml_changes(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[tuple[str, str, int]] = []
    monkeypatch.setattr(ssh, "warm", lambda host: seen.append((host.user, host.ip, host.ssh_port)))
    monkeypatch.setattr(warmup, "WARMED", set())
    robot_yaml = tmp_path / "robot.yaml"
    robot_yaml.write_text("# the project's file\n")
    context.warm_remote_hosts(_project(tmp_path), ["sync"])
    assert seen == [("root", "10.0.0.5", 22)]
    assert "10.0.0.5" in ProjectFolder(tmp_path).ssh_hosts_record.read_text()

    def next_command(argv: list[str], cwd: Path = tmp_path) -> list[tuple[str, str, int]]:
        seen.clear()
        monkeypatch.setattr(warmup, "WARMED", set())  # a new process
        warmup.warm_recorded(argv, cwd=cwd)
        return list(seen)

    elsewhere = tmp_path.parent
    assert next_command(["build", "sync", "run"]) == [("root", "10.0.0.5", 22)]
    assert next_command(["-p", str(tmp_path), "status"], cwd=elsewhere) == [("root", "10.0.0.5", 22)]
    assert next_command([f"--project={tmp_path}", "logs"], cwd=elsewhere) == [("root", "10.0.0.5", 22)]
    assert next_command([str(tmp_path), "run"], cwd=elsewhere) == [("root", "10.0.0.5", 22)]
    assert next_command(["build"]) == []  # nothing remote follows
    assert next_command(["sync", "--dry-run"]) == []
    assert next_command(["sync"], cwd=elsewhere) == []  # not the project folder: no record there
    robot_yaml.write_text("# the project's file, edited: hosts may have moved\n")
    assert next_command(["sync"]) == []
    ProjectFolder(tmp_path).ssh_hosts_record.write_text("{not json")
    assert next_command(["sync"]) == []


def test_warm_starts_ssh_in_the_background_and_does_not_wait(monkeypatch: pytest.MonkeyPatch) -> None:
    started: list[list[str]] = []

    class FakePopen:
        def __init__(self, argv: list[str], **kwargs: object) -> None:
            started.append(argv)
            assert kwargs.get("start_new_session") is True

    monkeypatch.setattr(ssh.subprocess, "Popen", FakePopen)
    monkeypatch.setattr("shutil.which", lambda name: "/usr/bin/ssh")
    ssh.warm(Host(name="main", ip="10.0.0.5", user="robot"))
    assert started and started[0][0] == "ssh" and started[0][-2:] == ["robot@10.0.0.5", "true"]
    assert "ControlMaster=auto" in started[0]
