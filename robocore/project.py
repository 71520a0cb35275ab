"""A robot project: its folder, its robot.yaml and the layout of what robocore keeps in ``.robocore/``.

:class:`ProjectFolder` names every path under ``.robocore/`` (generated files, caches and the
records commands leave for each other), and nothing else does. It needs no robot.yaml, so the
command line's first steps (the ssh warm-up) can use it before the config model is imported;
:class:`Project` adds the validated robot.
"""

from __future__ import annotations

import functools
import platform
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from robocore.errors import UsageError
from robocore.files import FLEET_FILE, ROBOT_FILE, STATE_DIR, check_no_links

if TYPE_CHECKING:
    from robocore.config.fleet import Fleet
    from robocore.config.model import Component, Host, Robot

#: The folders robocore writes directly under ``.robocore/`` (checked for links before a task writes).
STATE_FOLDERS = ("build", "cache", "compose", "dds", "desktop", "history", "home", "noop", "releases", "shell",
                 "sync", "test-results", "test-runs", "x11")
#: Inside a component's build folder: the state of its last successful build (package hashes, files, copies).
BUILD_STATE = ".robocore-build.json"
#: Inside a component's build folder: the state of its last successful build on its host (``builds_here``).
HOST_BUILD_STATE = ".robocore-host-build.json"


@dataclass(frozen=True)
class ProjectFolder:
    """A project folder and where each generated file, cache and record of robocore is in it."""

    root: Path

    @property
    def robot_file(self) -> Path:
        """The robot.yaml path."""
        return self.root / ROBOT_FILE

    @property
    def fleet_file(self) -> Path:
        """The fleet file path (fleet.yaml, next to robot.yaml; a project may have none)."""
        return self.root / FLEET_FILE

    @property
    def has_fleet(self) -> bool:
        """True when something is at the fleet file's path (loading it then says what is wrong with it)."""
        return self.fleet_file.is_symlink() or self.fleet_file.exists()

    @functools.cached_property  # every container name and label holds it: 10,000 components ask 20,000 times
    def name(self) -> str:
        """Project name: the folder name, lower-cased for image and container names."""
        return _slug(self.root.name)

    @property
    def state_dir(self) -> Path:
        """Folder of generated files (git-ignored)."""
        return self.root / STATE_DIR

    def build_dir(self, component: str) -> Path:
        """Where colcon puts build/, install/ and log/ of ``component``."""
        return self.state_dir / "build" / component

    def build_state_file(self, component: str) -> Path:
        """The state of ``component``'s last successful build, beside its colcon folders."""
        return self.build_dir(component) / BUILD_STATE

    def host_build_state_file(self, component: str) -> Path:
        """The state of ``component``'s last successful build on its host (a host with ``builds_here``)."""
        return self.build_dir(component) / HOST_BUILD_STATE

    @property
    def build_lock(self) -> Path:
        """The lock file that lets one graph-test run of the project build at a time."""
        return self.state_dir / "build.lock"

    @property
    def compose_dir(self) -> Path:
        """Folder of the generated per-host compose files."""
        return self.state_dir / "compose"

    def compose_file(self, host: str) -> Path:
        """The generated compose file of ``host``."""
        return self.compose_dir / f"{host}.yaml"

    @property
    def dds_dir(self) -> Path:
        """The generated Fast DDS profiles (mounted into every container)."""
        return self.state_dir / "dds"

    @property
    def cache_dir(self) -> Path:
        """Downloads kept between runs: git checkouts, the bootstrapped root file system."""
        return self.state_dir / "cache"

    def sync_state_file(self, host: str) -> Path:
        """What was last synced to ``host``: release id and tree digest per component."""
        return self.state_dir / "sync" / f"{host}.json"

    def sync_links_dir(self, host: str, component: str) -> Path:
        """The folder of symlinks to ``component``'s read-only project volumes, as sync sends them to ``host``."""
        return self.state_dir / "sync" / "files" / host / component

    def history_file(self, host: str) -> Path:
        """What ``run`` deployed on ``host``, oldest first (what ``rollback`` returns to)."""
        return self.state_dir / "history" / f"{host}.json"

    @property
    def releases_dir(self) -> Path:
        """The records of fleet releases (``<version>.json``: every image by digest), private to the user."""
        return self.state_dir / "releases"

    @property
    def test_results_dir(self) -> Path:
        """The merged JUnit XML of the last ``test`` run, one folder per component."""
        return self.state_dir / "test-results"

    @property
    def test_runs_dir(self) -> Path:
        """One folder per graph-test run (its DDS profiles)."""
        return self.state_dir / "test-runs"

    @property
    def ssh_hosts_record(self) -> Path:
        """The ssh hosts the last command warmed, for the next command to warm first."""
        return self.state_dir / "ssh-hosts.json"

    @property
    def schema_file(self) -> Path:
        """robot.yaml's JSON Schema, for editors."""
        return self.state_dir / "robot.schema.json"

    @property
    def fleet_schema_file(self) -> Path:
        """fleet.yaml's JSON Schema, for editors."""
        return self.state_dir / "fleet.schema.json"

    @property
    def shell_dir(self) -> Path:
        """The dev shell's setup files (mounted read-only into dev containers)."""
        return self.state_dir / "shell"

    def home_dir(self, user: str) -> Path:
        """The developer's persistent home in dev containers."""
        return self.state_dir / "home" / user

    def x11_dir(self, container: str) -> Path:
        """The folder of a dev container's xauth cookie (a folder, so the file can be replaced atomically)."""
        return self.state_dir / "x11" / container

    @property
    def desktop_dir(self) -> Path:
        """The folder of the desktop's VNC password (0700, the file 0600)."""
        return self.state_dir / "desktop"

    def check_state_links(self) -> None:
        """Refuse, in one line naming it, a symlink at ``.robocore`` or at any folder robocore writes below it
        (a cloned repository can carry one): checked with lstat before a task writes anything, so that nothing
        outside the project is written or removed through it. Folders below these are checked as they are
        written (:func:`robocore.files.write_atomic` and its siblings)."""
        folders = [self.state_dir / name for name in STATE_FOLDERS]
        for path in (self.state_dir, *folders, self.ssh_hosts_record, self.schema_file, self.fleet_schema_file,
                     self.build_lock):
            check_no_links(path, anchor=self.root)


@dataclass(frozen=True)
class Project(ProjectFolder):
    """A robot project folder and its validated robot.yaml, as seen from the machine robocore runs on.

    ``native_arch`` is that machine's arch (Docker's name): its base image is ``<base>:latest``, another arch's
    ``<base>:latest-<arch>`` (:func:`robocore.plan.arches.base_tag`), so every image name planned from the
    project reads it. Tests pin it to plan as another machine would.
    """

    robot: Robot
    native_arch: str = field(default_factory=lambda: this_machine_arch())

    @classmethod
    def load(cls, root: Path) -> Project:
        """Load and validate ``root/robot.yaml``."""
        from robocore.config.loader import load_robot

        root = root.resolve()
        return cls(root=root, robot=load_robot(root))

    def load_fleet(self) -> Fleet:
        """Load and check ``fleet.yaml`` against this project's robot.yaml (ConfigError naming every problem)."""
        from robocore.config.fleet import load_fleet

        return load_fleet(self.root, self.robot)

    def component(self, name: str) -> Component:
        """The component called ``name``, or a UsageError listing the known ones."""
        try:
            return self.robot.component(name)
        except KeyError:
            known = ", ".join(c.name for c in self.robot.components) or "none"
            raise UsageError(f"unknown component {name!r} (known: {known})") from None

    def host(self, name: str) -> Host:
        """The host called ``name``, or a UsageError listing the known ones."""
        try:
            return self.robot.host(name)
        except KeyError:
            known = ", ".join(h.name for h in self.robot.hosts)
            raise UsageError(f"unknown host {name!r} (known: {known})") from None


def this_machine_arch() -> str:
    """The arch of the machine robocore runs on, in Docker's terms (``amd64``, ``arm64``)."""
    from robocore.config.model import docker_arch

    return docker_arch(platform.machine())


def _slug(text: str) -> str:
    out = "".join(ch if ch.isalnum() or ch in "-_." else "-" for ch in text.lower()).strip("-._")
    return out or "robot"
