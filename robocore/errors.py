"""The one error hierarchy of robocore.

Every failure a user can cause or fix is a :class:`RobocoreError`. The CLI edge
(:mod:`robocore.tasks`) turns it into one line per problem on stderr and its
``exit_code``; anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass


class RobocoreError(Exception):
    """Base of every error robocore reports to the user without a traceback."""

    exit_code = 1

    def __init__(self, message: str, *, hint: str | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.hint = hint

    def lines(self) -> list[str]:
        """Return the lines to print, one per problem, hint last."""
        out = [self.message]
        if self.hint:
            out.append(f"hint: {self.hint}")
        return out


@dataclass(frozen=True)
class Problem:
    """One problem in a configuration file: where it is and what is wrong."""

    file: str
    line: int | None
    path: str
    message: str
    #: ``error`` (the file is refused) or ``warning`` (allowed, but worth a reviewer's look).
    severity: str = "error"

    def __str__(self) -> str:
        where = f"{self.file}:{self.line}" if self.line is not None else self.file
        message = f"warning: {self.message}" if self.severity == "warning" else self.message
        # a key path is built from the file's own keys: a newline in one must not start a forged line
        path = self.path if self.path.isprintable() else repr(self.path)[1:-1]
        return f"{where}: {path}: {message}" if path else f"{where}: {message}"


class ConfigError(RobocoreError):
    """robot.yaml (or another input file) is missing, unreadable or invalid."""

    exit_code = 2

    def __init__(self, problems: Sequence[Problem]) -> None:
        self.problems = list(problems)
        super().__init__("\n".join(str(p) for p in self.problems))

    def lines(self) -> list[str]:
        """One line per problem."""
        return [str(p) for p in self.problems]


class UsageError(RobocoreError):
    """The command line asks for something that does not exist (a component, a host...)."""

    exit_code = 2


class ArchMismatch(UsageError):
    """Something of one CPU arch would go where another runs: an install tree synced to a host of another arch,
    a host whose daemon cannot run its arch."""


class UnsafePath(RobocoreError):
    """A file or folder robocore would read, copy or connect through is not safe to use: a symlink
    leading out of the project, a folder another user owns or may write to."""

    exit_code = 2


class ToolMissing(RobocoreError):
    """An outside program robocore needs (mmdebstrap, rsync, ssh, ...) is not installed."""

    exit_code = 4


class DockerError(RobocoreError):
    """A Docker daemon could not be reached or refused an operation."""

    exit_code = 5


class BuildError(RobocoreError):
    """An image build or a colcon build failed."""

    exit_code = 6


class HostError(RobocoreError):
    """A robot host is unreachable or an operation on it failed."""

    exit_code = 7


class GroupError(RobocoreError):
    """Several hosts were tried; some failed. Carries the per-host outcome."""

    exit_code = 8

    def __init__(self, failures: dict[str, RobocoreError], succeeded: Sequence[str]) -> None:
        self.failures = failures
        self.succeeded = list(succeeded)
        super().__init__(f"{len(failures)} host(s) failed")

    def lines(self) -> list[str]:
        """One line per failed host, then which hosts succeeded."""
        out = []
        for host, err in sorted(self.failures.items()):
            first, *rest = err.lines()
            out.append(f"{host}: {first}")
            out.extend(f"{host}: {line}" for line in rest)
        if self.succeeded:
            out.append("succeeded: " + ", ".join(sorted(self.succeeded)))
        return out


class TestFailure(RobocoreError):
    """Package tests failed or errored, their results could not be read, or colcon test could not run."""

    __test__ = False  # not a pytest test class, whatever imports it
    exit_code = 9
