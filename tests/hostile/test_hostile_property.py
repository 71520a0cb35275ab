"""Property: robot.yaml documents with hostile strings in their fields load into a Robot or a
ConfigError, never anything else; every value robocore accepts for a host address, mount root,
image, registry, git URL/version/branch or pip/apt entry starts with no ``-`` and holds no control
character, and reaches the argv (or Dockerfile line) robocore builds for it as one unchanged argument.

The argv builders are robocore's public functions: :func:`robocore.adapters.vcs.fetch` (its git
calls are recorded instead of run), :func:`robocore.adapters.ssh.ssh_argv`,
:func:`robocore.plan.sync.rsync_argv` and ``session_argv``, and the Dockerfiles of
:mod:`robocore.plan.dockerfiles`.
"""

from __future__ import annotations

import contextlib
import re
import shlex
import subprocess
import tempfile
from pathlib import Path, PurePosixPath
from typing import Any
from unittest import mock

import yaml
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from robocore.adapters import ssh, vcs
from robocore.config.loader import parse_robot_text
from robocore.config.model import Robot
from robocore.errors import ConfigError, RobocoreError
from robocore.plan import arches, dockerfiles
from robocore.plan import sync as sync_plan

PROPERTY = settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")

HOSTILE = [
    "-oProxyCommand=touch /tmp/robocore-hostile", "--upload-pack=touch /tmp/robocore-hostile", "-u", "-", "--",
    "$(touch /tmp/robocore-hostile)", "a;touch /tmp/robocore-hostile", "`id`", "a\nRUN id", "\x1b[31m", "a\x00b",
    "\u202eevil", " ", "", "a b", "../..", "/", "~", ".", "..", "ext::sh -c id", "file:///etc", "/etc/passwd",
    "fd::3", "-r/etc/passwd", "--index-url=http://x", "-o APT::Update::Pre-Invoke::=id", "root@10.0.0.1",
    "10.0.0.1:22", "fe80::1%eth0", "2001:db8::1", "a" * 300, "main..dev", "HEAD^", "x.lock", "https://u:p@h.io/x",
    "host:-x", "ssh://-oProxyCommand=id/x", "Debian:12", "busybox\nRUN id", "pkg; touch x", "/srv/../etc",
]


BAD = st.one_of(st.sampled_from(HOSTILE), st.text(max_size=16), st.text(alphabet="-.:/@ ;$`\n\x1baz09", max_size=10))

#: Valid values of each field (a document corrupts up to two fields, the rest come from here).
VALID: dict[str, tuple[str | None, ...]] = {
    "ip": ("192.168.1.10", "10.0.0.5", "pi5.local", "robot-1", "x1.example.com", "127.0.0.1"),
    "mount_root": (None, "/srv/robot", "/opt/r-1/x", "/srv/robot/"),
    "base_image": (None, "ros:jazzy-ros-base", "debian:bookworm", "ghcr.io/org/img:v1",
                   "localhost:5000/x@sha256:" + "a" * 64),
    "image": ("busybox", "ghcr.io/x/y:1", "registry.local:5000/team/viewer:v2"),
    "registry": (None, "docker.io/team", "localhost:5000", "ghcr.io/org/"),
    "image_prefix": ("", "robot-", "team/robot-"),
    "url": ("https://github.com/ros/common_msgs.git", "git@github.com:ros/x.git", "ssh://git@host.local:2222/r.git",
            "https://h.example/a/b"),
    "version": (None, "main", "humble", "v1.2.3", "feature/x", "0123abcd"),
    "repo": ("https://github.com/ros/msgs.git", "git@gitlab.com:team/msgs"),
    "branch": (None, "main", "v2"),
    "pip": ("numpy", "numpy>=1.26", "pkg[extra]==1.0", "pkg; python_version<'3.12'"),
    "apt": ("curl", "ros-jazzy-tf2-ros", "libfoo=1.2-3", "python3-pip/bookworm-backports"),
}


def _set(mapping: dict[str, Any], key: str, value: Any) -> None:
    if value is not None:
        mapping[key] = value


@st.composite
def documents(draw: st.DrawFn) -> dict[str, Any]:
    """A robot: one host, a component with packages and a repository, one on an image, a common package;
    up to two of its fields hold hostile or random text."""
    corrupt = draw(st.sets(st.sampled_from(sorted(VALID)), max_size=2))

    def value(name: str) -> Any:
        return draw(BAD if name in corrupt else st.sampled_from(VALID[name]))

    host: dict[str, Any] = {"name": "main", "ip": value("ip"), "user": "robot"}
    _set(host, "mount_root", value("mount_root"))
    repository: dict[str, Any] = {"url": value("url")}
    _set(repository, "version", value("version"))
    builder = {
        "name": "talker", "runs_on": "main", "repositories": [repository],
        "apt_packages": [value("apt") for _ in range(draw(st.integers(0, 2)))],
        "pip_packages": [value("pip") for _ in range(draw(st.integers(0, 2)))],
    }
    common: dict[str, Any] = {"name": "msgs", "repo": value("repo")}
    _set(common, "branch", value("branch"))
    doc: dict[str, Any] = {
        "ros_distro": "jazzy",
        "image_prefix": value("image_prefix"),
        "hosts": [host],
        "components": [builder, {"name": "viewer", "runs_on": "main", "image": value("image")}],
        "common_packages": [common],
    }
    _set(doc, "registry", value("registry"))
    base_image = value("base_image")
    if base_image is not None:
        doc["base"] = {"image": base_image}
    return doc


def safe(value: str) -> None:
    assert not value.startswith("-"), value
    assert CONTROL.search(value) is None, repr(value)


def git_argvs(url: str, version: str | None) -> list[list[str]]:
    """The argv lists robocore's git adapter runs to fetch ``url`` at ``version`` (recorded, not run)."""
    calls: list[list[str]] = []

    def record(argv: list[str], *args: Any, cwd: Any = None, **kwargs: Any) -> subprocess.CompletedProcess[str]:
        calls.append(list(argv))
        if cwd is not None and "init" in argv:
            (Path(cwd) / ".git").mkdir(exist_ok=True)
        return subprocess.CompletedProcess(argv, 0, "0" * 40 + "\n", "")

    with (tempfile.TemporaryDirectory() as tmp, mock.patch("subprocess.run", record),
          mock.patch("shutil.which", lambda name, *a, **k: f"/usr/bin/{name}"),
          contextlib.suppress(OSError, RobocoreError)):  # only the recorded argv matters here
        vcs.fetch(url, version, Path(tmp) / "checkout")
    return calls


def check_argvs(robot: Robot) -> None:
    host = robot.hosts[0]
    destination = f"{host.user}@{host.ip}"
    assert destination in ssh.ssh_argv(host, ["true"])
    assert host.deploy_root in sync_plan.session_argv(host.deploy_root, "tester", [])
    item = sync_plan.ComponentSync("talker", host.name, PurePosixPath(host.deploy_root) / "talker", (), "")
    assert f"{destination}:{item.staging}/" in sync_plan.rsync_argv(item, host, "ssh")
    sources = [(r.url, r.version) for c in robot.components for r in c.repositories]
    sources += [(p.repo, p.branch) for p in robot.common_packages if p.repo]
    for url, version in sources:
        calls = git_argvs(url, version)
        assert any(url in argv for argv in calls), calls
        if version:
            assert any(version in argv for argv in calls), calls
    base = dockerfiles.base_dockerfile(robot, root_image=arches.upstream_root(robot), has_ca=False, common=[])
    assert f"FROM {arches.upstream_root(robot)}" in base.splitlines()
    builder = robot.components[0]
    text = dockerfiles.component_dockerfile(robot, builder, base_ref="robot-base:latest")
    runs = [shlex.split(line) for line in text.splitlines() if line.startswith("RUN ") and "install" in line]
    for entry in [*builder.pip_packages, *builder.apt_packages]:
        assert any(entry in tokens for tokens in runs), (entry, text)


@PROPERTY
@given(documents())
def test_hostile_strings_in_every_field(doc: dict[str, Any]) -> None:
    text = yaml.safe_dump(doc, allow_unicode=True)
    try:
        robot = parse_robot_text(text)
    except ConfigError as error:
        event("refused")
        for line in error.lines():
            assert line.startswith("robot.yaml") and line.isprintable(), line
        return
    event("accepted")
    host = robot.hosts[0]
    for value in [host.ip, host.user, host.deploy_root, robot.image_prefix or "x", robot.registry or "x",
                  robot.base.image or "x", *(c.image or "x" for c in robot.components)]:
        safe(value)
    for comp in robot.components:
        for repo in comp.repositories:
            safe(repo.url)
            safe(repo.version or "x")
            safe(repo.checkout_folder)
        for entry in [*comp.pip_packages, *comp.apt_packages]:
            safe(entry)
    for pkg in robot.common_packages:
        safe(pkg.repo or "x")
        safe(pkg.branch or "x")
    check_argvs(robot)


def test_the_valid_pools_are_accepted_and_reach_the_argvs() -> None:
    """A negative control: the strategy's valid values make a robot that loads, so acceptance is exercised."""
    doc = {
        "ros_distro": "jazzy", "image_prefix": "robot-", "registry": "docker.io/team",
        "base": {"image": "ros:jazzy-ros-base"},
        "hosts": [{"name": "main", "ip": "pi5.local", "user": "robot", "mount_root": "/srv/robot/"}],
        "components": [
            {"name": "talker", "runs_on": "main", "apt_packages": ["curl"], "pip_packages": ["numpy>=1.26"],
             "repositories": [{"url": "git@github.com:ros/x.git", "version": "humble"}]},
            {"name": "viewer", "runs_on": "main", "image": "ghcr.io/x/y:1"},
        ],
        "common_packages": [{"name": "msgs", "repo": "https://github.com/ros/common_msgs.git", "branch": "main"}],
    }
    robot = parse_robot_text(yaml.safe_dump(doc))
    assert robot.hosts[0].deploy_root == "/srv/robot"
    check_argvs(robot)
    calls = git_argvs("git@github.com:ros/x.git", "humble")
    assert any("git@github.com:ros/x.git" in argv and "humble" in argv for argv in calls), calls
