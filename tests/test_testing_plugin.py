"""The pytest plugin's surface without Docker: options, project discovery, environment checks, run owners."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from robocore.testing import bringup, domains, ros_env


def test_the_plugin_is_registered_and_documents_its_option(pytester: pytest.Pytester) -> None:
    result = pytester.runpytest("--help")
    result.stdout.fnmatch_lines(["*--robocore-project=DIR*"])


def test_a_project_option_without_robot_yaml_is_one_usage_error(pytester: pytest.Pytester) -> None:
    pytester.makepyfile("def test_x(robot):\n    pass\n")
    result = pytester.runpytest("--robocore-project", str(pytester.path / "missing"))
    assert result.ret != 0
    result.stdout.fnmatch_lines(["*--robocore-project*no robot.yaml in*"])
    assert "Traceback" not in result.stdout.str()


def test_no_robot_yaml_above_the_tests_is_one_usage_error(pytester: pytest.Pytester) -> None:
    pytester.makepyfile("def test_x(robot):\n    pass\n")
    result = pytester.runpytest()
    assert result.ret != 0
    result.stdout.fnmatch_lines(["*found no robot.yaml above*--robocore-project DIR*"])


def test_tests_without_the_fixture_never_touch_docker(pytester: pytest.Pytester,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DOCKER_HOST", "unix:///nonexistent.sock")
    (pytester.path / "robot.yaml").write_text("not: [valid\n")  # even a broken project is never read
    pytester.makepyfile("def test_plain():\n    assert 1 + 1 == 2\n")
    result = pytester.runpytest_subprocess()
    result.assert_outcomes(passed=1)


@pytest.mark.parametrize(("wanted", "found", "expected"), [
    ("humble", None, "humble has no wheels on PyPI (wheels exist for jazzy, kilted)"),
    ("kilted", "jazzy", "which has rclpy for jazzy: pip install 'robocore[testing-kilted]'"),
    ("jazzy", None, "which has no ROS 2 wheels: pip install 'robocore[testing]'"),
])
def test_a_distro_without_matching_wheels_is_one_line(monkeypatch: pytest.MonkeyPatch, wanted: str,
                                                      found: str | None, expected: str) -> None:
    monkeypatch.setattr(ros_env, "installed_distro", lambda: found)
    with pytest.raises(ros_env.TestEnvironmentError) as caught:
        ros_env.check_distro(wanted)
    (line,) = caught.value.lines()
    assert expected in line


def test_this_environment_has_the_jazzy_wheels() -> None:
    assert ros_env.installed_distro() == "jazzy"
    ros_env.check_distro("jazzy")


def test_a_live_owner_is_never_reaped_and_a_dead_one_is() -> None:
    assert not bringup.owner_is_gone(bringup.owner())
    host, boot, pid, ticks = bringup.owner().split("|")
    assert bringup.owner_is_gone(f"{host}|{boot}|{pid}|{int(ticks) + 1}")  # same pid, another process
    assert bringup.owner_is_gone(f"{host}|{boot}|999999999|1")
    assert not bringup.owner_is_gone(f"another-machine|{boot}|999999999|1")  # a shared daemon: not ours
    assert not bringup.owner_is_gone("garbage")


def test_domains_are_reserved_once_per_machine() -> None:
    first, holder = domains.reserve_domain()
    try:
        with socket.socket() as probe, pytest.raises(OSError):
            probe.bind(("127.0.0.1", domains.DOMAIN_LOCK_PORT + first))
        second, other = domains.reserve_domain()
        other.close()
        assert second != first
    finally:
        holder.close()


class _Running:
    """The local daemon's robocore containers, as ``domains_in_use`` reads them."""

    def __init__(self, envs: list[list[str]]) -> None:
        self.containers = self
        self._envs = envs

    def list(self, **_: object) -> list[object]:
        return [type("C", (), {"attrs": {"Config": {"Env": env}}})() for env in self._envs]


def test_a_domain_a_robot_runs_here_in_is_never_handed_out(monkeypatch: pytest.MonkeyPatch) -> None:
    """A robot deployed here (a developer's, another suite's) holds no reservation: its containers' ROS_DOMAIN_ID
    keeps the domain from every run (two robots of one domain on one host share its ports)."""
    monkeypatch.setattr(domains, "DOMAINS", range(1, 4))
    running = _Running([["ROS_DOMAIN_ID=1", "PATH=/usr/bin"], ["ROS_DOMAIN_ID=3"], ["ROS_DOMAIN_ID=x"], []])
    assert domains.domains_in_use(running) == {1, 3}
    for _ in range(5):
        domain, holder = domains.reserve_domain(running)
        holder.close()
        assert domain == 2
    with pytest.raises(bringup.BringUpError, match="used by a robot running here"):
        held = domains.hold_domain(2)
        try:
            domains.reserve_domain(running)
        finally:
            assert held is not None
            held.close()
    assert domains.reserve_domain()[0] in {1, 2, 3}  # the control: without the daemon's word, any domain


def test_install_trees_of_another_python_are_named(tmp_path: Path) -> None:
    site = tmp_path / "my_msgs" / "lib" / "python3.99" / "site-packages"
    site.mkdir(parents=True)
    (problem,) = ros_env.add_install_tree(tmp_path)
    assert problem.startswith("my_msgs: built for python3.99") and "robot.exec" in problem
