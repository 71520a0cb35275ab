"""The release plan: one tag per arch, one manifest list per image, the docker manifest argv, when the CLI
must speak plain http to the registry (no I/O)."""

from __future__ import annotations

from pathlib import Path

import pytest

from robocore.commands.release import released_images
from robocore.config.model import Robot
from robocore.errors import UsageError
from robocore.plan import containers
from robocore.plan import release as plan
from robocore.project import Project

IMAGES = [plan.LocalImage("r-base", "amd64", "r-base:latest"),
          plan.LocalImage("r-base", "arm64", "r-base:latest-arm64"),
          plan.LocalImage("r-talker", "arm64", "r-talker:latest"),
          plan.LocalImage("r-listener", "amd64", "r-listener:latest")]


def test_each_arch_is_pushed_under_its_own_tag_and_named_by_one_list() -> None:
    release = plan.plan_release("reg.example:5000/team/", "v1", IMAGES)
    assert [(p.source, p.ref) for p in release.pushes] == [
        ("r-base:latest", "reg.example:5000/team/r-base:v1-amd64"),
        ("r-base:latest-arm64", "reg.example:5000/team/r-base:v1-arm64"),
        ("r-talker:latest", "reg.example:5000/team/r-talker:v1-arm64"),
        ("r-listener:latest", "reg.example:5000/team/r-listener:v1-amd64"),
    ]
    assert [(m.ref, m.members) for m in release.lists] == [
        ("reg.example:5000/team/r-base:v1", ("reg.example:5000/team/r-base:v1-amd64",
                                             "reg.example:5000/team/r-base:v1-arm64")),
        ("reg.example:5000/team/r-talker:v1", ("reg.example:5000/team/r-talker:v1-arm64",)),
        ("reg.example:5000/team/r-listener:v1", ("reg.example:5000/team/r-listener:v1-amd64",)),
    ]


def test_manifest_argv_are_lists_with_operands_after_dashes() -> None:
    [base, *_] = plan.plan_release("127.0.0.1:5000", "v1", IMAGES).lists
    assert plan.manifest_create_argv("/usr/bin/docker", base, insecure=True) == [
        "/usr/bin/docker", "manifest", "create", "--amend", "--insecure", "--", "127.0.0.1:5000/r-base:v1",
        "127.0.0.1:5000/r-base:v1-amd64", "127.0.0.1:5000/r-base:v1-arm64"]
    assert plan.manifest_push_argv("docker", base, insecure=False) == [
        "docker", "manifest", "push", "--purge", "--", "127.0.0.1:5000/r-base:v1"]


def test_a_version_too_long_for_the_arch_tags_is_refused() -> None:
    with pytest.raises(UsageError, match="not a valid image tag"):
        plan.plan_release("reg", "v" * 125, IMAGES)


@pytest.mark.parametrize(("registry", "config", "expected"), [
    ("127.0.0.1:5000", {}, True),
    ("localhost:5000/team", {}, True),
    ("[::1]:5000", {}, True),
    ("reg.example:5000", {}, False),
    ("reg.example:5000", {"IndexConfigs": {"reg.example:5000": {"Secure": False}}}, True),
    ("reg.example:5000", {"IndexConfigs": {"reg.example:5000": {"Secure": True}}}, False),
    ("10.1.2.3:5000", {"InsecureRegistryCIDRs": ["10.0.0.0/8"]}, True),
    ("192.168.1.3:5000", {"InsecureRegistryCIDRs": ["10.0.0.0/8", "not a cidr"]}, False),
])
def test_plain_http_follows_what_the_daemon_trusts(registry: str, config: dict[str, object], expected: bool) -> None:
    assert plan.plain_http(registry, config) is expected


def test_released_references_are_those_under_the_registry() -> None:
    assert plan.is_released("reg:5000/", "reg:5000/r-base:v1")
    assert not plan.is_released("reg:5000", "r-base:latest")
    assert not plan.is_released(None, "reg:5000/r-base:v1")


def test_a_mixed_robot_releases_the_base_of_each_arch_and_each_component_of_its_hosts_arch(tmp_path: Path) -> None:
    robot = Robot.model_validate({
        "ros_distro": "noetic", "base": {"kind": "debian"}, "registry": "127.0.0.1:5000",
        "hosts": [{"name": "nuc", "ip": "10.0.0.5"}, {"name": "jetson", "ip": "10.0.0.7", "arch": "arm64"}],
        "components": [{"name": "talker", "runs_on": "jetson", "folder": "t"},
                       {"name": "listener", "runs_on": "nuc", "folder": "l"}],
    })
    images = released_images(Project(root=tmp_path / "r", robot=robot))
    assert {(i.repo, i.arch) for i in images} == {("r-base", "amd64"), ("r-base", "arm64"), ("r-talker", "arm64"),
                                                  ("r-listener", "amd64")}
    assert {i.source for i in images if i.repo != "r-base"} == {"r-talker:latest", "r-listener:latest"}


def test_a_robot_with_no_x86_host_releases_the_arm64_base_its_server_runs(tmp_path: Path) -> None:
    """One Jetson on the official base (jazzy), released from an amd64 machine: the arm64 base (which its Fast
    DDS server runs) and the talker, each of arm64, and nothing of amd64; the host runs the release's names."""
    robot = Robot.model_validate({
        "ros_distro": "jazzy", "base": {"kind": "official"}, "registry": "127.0.0.1:5000",
        "hosts": [{"name": "jetson", "ip": "10.0.0.7", "arch": "arm64"}],
        "components": [{"name": "talker", "runs_on": "jetson", "folder": "t"}],
    })
    project = Project(root=tmp_path / "r", robot=robot, native_arch="amd64")
    images = released_images(project)
    assert {(i.repo, i.arch, i.source) for i in images} == {("r-base", "arm64", "r-base:latest-arm64"),
                                                            ("r-talker", "arm64", "r-talker:latest")}
    pushed = plan.plan_release("127.0.0.1:5000", "v1", images)
    assert {p.arch for p in pushed.pushes} == {"arm64"}
    server, talker = containers.host_specs(project, "jetson", tag="v1")
    assert (server.role, server.image) == ("discovery", "127.0.0.1:5000/r-base:v1")
    assert talker.image == "127.0.0.1:5000/r-talker:v1"
