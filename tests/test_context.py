"""Loading a project opens the robot hosts' ssh connections early, only when a remote step follows."""

from __future__ import annotations

from pathlib import Path

import pytest

from robocore.adapters import ssh
from robocore.commands import context
from robocore.config.model import Host, Robot
from robocore.project import Project


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


@pytest.mark.parametrize(("argv", "warmed"), [
    (["build", "--component", "a", "sync", "run"], ["main"]),  # ssh hosts that run something; not spare
    (["-p", "x", "status"], ["main"]),
    (["build"], []),  # nothing remote follows
    (["sync", "--dry-run"], []),  # a dry run contacts nobody
])
def test_ssh_hosts_are_warmed_only_before_remote_steps(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                       argv: list[str], warmed: list[str]) -> None:
    seen: list[str] = []
    monkeypatch.setattr(ssh, "warm", lambda host: seen.append(host.name))
    project = _project(tmp_path)
    context.warm_remote_hosts(project, argv)
    context.warm_remote_hosts(project, argv)  # once per process
    assert seen == warmed


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
