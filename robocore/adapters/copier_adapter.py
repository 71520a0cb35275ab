"""The copier adapter: render robocore's project template into a folder.

copier is imported inside the functions so that ``robocore --help`` stays fast. Every copier
failure becomes a :class:`~robocore.errors.RobocoreError` here, and only here.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from robocore.errors import RobocoreError, ToolMissing, UsageError

#: Environment variable that points robocore at another copy of the template (folder or git URL).
TEMPLATE_ENV = "ROBOCORE_TEMPLATE"

#: The answers file copier writes into a generated project (template/copier.yml: _answers_file).
ANSWERS_FILE = ".copier-answers.yml"


class TemplateError(RobocoreError):
    """copier could not render the project template."""

    exit_code = 2


def bundled_template() -> Path:
    """The template that comes with this robocore: ``template/`` of its source tree, else the wheel's copy.

    An editable install runs from robocore's repository, whose top-level ``template/`` is the
    template; a built wheel carries a copy as ``robocore/resources/template`` (setup.py).
    """
    package = Path(__file__).resolve().parent.parent
    candidates = (package.parent / "template", package / "resources" / "template")
    for candidate in candidates:
        if (candidate / "copier.yml").is_file():
            return candidate
    looked = ", ".join(str(c) for c in candidates)
    raise ToolMissing(
        f"robocore's project template was not found (looked in {looked})",
        hint=f"set {TEMPLATE_ENV} to a copy of robocore's template/ folder or its git URL",
    )


@dataclass(frozen=True)
class CopyRequest:
    """One rendering of the template: what goes where, with which answers."""

    template: str
    destination: Path
    data: Mapping[str, Any] = field(default_factory=dict)
    """Answers given up front: these questions are not asked."""
    user_defaults: Mapping[str, Any] = field(default_factory=dict)
    """Defaults offered when asking (and used as answers with ``defaults``)."""
    defaults: bool = False
    """Ask nothing: every unanswered question takes its default."""
    pretend: bool = False
    """Only print what would be written."""
    keep_existing: bool = False
    """Never overwrite a file that already exists in ``destination``."""
    vcs_ref: str | None = None
    """Git tag or commit of a template that lives in a git repository."""


@contextmanager
def _copier_errors(what: str) -> Iterator[None]:
    """Turn copier's exceptions into one-line robocore errors."""
    from copier.errors import CopierError, InteractiveSessionError, UnsafeTemplateError
    from plumbum.commands.processes import ProcessExecutionError

    try:
        yield
    except InteractiveSessionError:
        raise UsageError(
            f"{what}: copier needs a terminal to ask its questions",
            hint="answer with defaults: add --defaults (and --distro/--base to choose those)",
        ) from None
    except UnsafeTemplateError as error:
        raise TemplateError(f"{what}: {_one_line(error)}", hint="robocore's template never needs --trust") from None
    except KeyboardInterrupt:
        raise
    except CopierError as error:
        raise TemplateError(f"{what}: {_one_line(error)}") from None
    except ValueError as error:  # copier's answer validation (pydantic / validator messages)
        raise TemplateError(f"{what}: {_one_line(error)}") from None
    except ProcessExecutionError as error:  # copier runs git through plumbum: an unreachable or broken repository
        raise TemplateError(f"{what}: {_git_failure(error)}",
                            hint="check that the template source is a git repository you can read") from None


def _git_failure(error: Any) -> str:
    """``git ls-remote`` failed (exit 128): fatal: ... as one line, from a plumbum ProcessExecutionError."""
    argv = [str(arg) for arg in (getattr(error, "argv", None) or [])]
    tool = " ".join(Path(argv[0]).name.split() + argv[1:2]) if argv else "git"
    lines = [line.strip() for line in str(getattr(error, "stderr", "") or "").splitlines() if line.strip()]
    said = lines[0] if lines else f"exit code {getattr(error, 'retcode', '?')}"
    return f"{tool} failed: {said}"


def _one_line(error: BaseException) -> str:
    text = " ".join(str(error).split())
    return text or type(error).__name__


def copy(request: CopyRequest) -> None:
    """Render the template into ``request.destination``."""
    import copier

    from robocore.files import creating_for_this_user, narrow_new

    skip = ("*", "**", ".*") if request.keep_existing else ()
    destination = request.destination
    before = {Path(here) / name for here, dirs, names in os.walk(destination) for name in [*dirs, *names]} \
        if request.keep_existing else set()
    before |= {destination} if os.path.lexists(destination) else set()
    # nothing the template makes may be written by others, whatever the umask (anyone local could replace tasks.py)
    with _copier_errors(f"{request.destination}: copying template {request.template}"), creating_for_this_user():
        copier.run_copy(
            request.template,
            request.destination,
            data=dict(request.data),
            user_defaults=dict(request.user_defaults),
            defaults=request.defaults,
            pretend=request.pretend,
            skip_if_exists=skip,
            overwrite=request.keep_existing,
            vcs_ref=request.vcs_ref,
            unsafe=False,
            quiet=False,
        )
    if not request.pretend and os.path.isdir(destination):
        narrow_new(destination, before)


def update(destination: Path, *, defaults: bool = True, pretend: bool = False, vcs_ref: str | None = None) -> None:
    """``copier update`` a generated project to the template's latest (or ``vcs_ref``) version."""
    import copier

    answers = destination / ANSWERS_FILE
    if not answers.is_file():
        raise UsageError(f"{answers}: missing; the project was not generated by copier and cannot be updated")
    with _copier_errors(f"{destination}: updating from the template"):
        copier.run_update(
            destination,
            defaults=defaults,
            pretend=pretend,
            vcs_ref=vcs_ref,
            overwrite=True,
            skip_answered=True,
            unsafe=False,
            conflict="inline",
        )
