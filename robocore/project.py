"""A loaded robot project: its folder, its robot.yaml and where generated files go."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from robocore.config.loader import ROBOT_FILE, load_robot
from robocore.config.model import Component, Host, Robot
from robocore.errors import UsageError

STATE_DIR = ".robocore"


@dataclass(frozen=True)
class Project:
    """A robot project folder and its validated robot.yaml."""

    root: Path
    robot: Robot

    @classmethod
    def load(cls, root: Path) -> Project:
        """Load and validate ``root/robot.yaml``."""
        root = root.resolve()
        return cls(root=root, robot=load_robot(root))

    @property
    def robot_file(self) -> Path:
        """The robot.yaml path."""
        return self.root / ROBOT_FILE

    @property
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

    def compose_file(self, host: str) -> Path:
        """The generated compose file of ``host``."""
        return self.state_dir / "compose" / f"{host}.yaml"

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


def _slug(text: str) -> str:
    out = "".join(ch if ch.isalnum() or ch in "-_." else "-" for ch in text.lower()).strip("-._")
    return out or "robot"
