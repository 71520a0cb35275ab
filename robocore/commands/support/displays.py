"""The displays of deployed components: the host's own display for ``gui: true`` components (a cookie of
their own, made before ``run`` starts them), and the VNC password of the project's desktops.

A display manager gives the logged-in user a new cookie at every login, so the copy is made at
every ``run``, on the component's host and as that host's user (over ssh, or here for a local
host), by the fixed script of :mod:`robocore.plan.gui`. The container mounts the folder, not the
file, so a later copy reaches a running container too.
"""

from __future__ import annotations

import secrets
import string
import subprocess
from pathlib import Path

from robocore.config.model import Host
from robocore.errors import HostError
from robocore.files import PRIVATE, read_own_file, write_atomic
from robocore.plan import gui
from robocore.project import Project

#: Seconds the cookie script may take on a host.
COOKIE_TIMEOUT = 60
#: VNC authentication uses the first 8 characters of a password: 8 letters and digits (about 47 bits).
PASSWORD_LENGTH = 8
PASSWORD_ALPHABET = string.ascii_letters + string.digits


def valid_password(data: bytes | None) -> str | None:
    """``data`` as a password robocore made (its length and alphabet), else None."""
    text = (data or b"").decode("ascii", errors="replace")
    ok = len(text) == PASSWORD_LENGTH and all(ch in PASSWORD_ALPHABET for ch in text)
    return text if ok else None


def ensure_desktop_password(project: Project) -> Path | None:
    """The project's VNC password file, made once (``secrets``) when a desktop asks for it; None when none does.

    Mode 0600 in a 0700 folder, written through :func:`~robocore.files.write_atomic` (never through a link, never
    half-written); a file that is not robocore's own password (a link, a FIFO, something else) is replaced by a new
    one only if it is a regular file, refused otherwise. An existing password keeps its value, and its mode is
    narrowed to 0600."""
    if not any(gui.needs_password(c) for c in project.robot.components):
        return None
    path = gui.password_file(project)
    password = valid_password(read_own_file(path))
    if password is None:
        password = "".join(secrets.choice(PASSWORD_ALPHABET) for _ in range(PASSWORD_LENGTH))
    write_atomic(path, password, mode=PRIVATE)
    return path


def prepare_host_displays(project: Project, host: Host, *, dry_run: bool) -> list[str]:
    """Copy the host user's cookie for each ``gui: true`` component of ``host``; notes for the run summary.

    Nothing happens in a dry run, nor on a host without such components. A missing ``xauth`` or
    cookie is a note, not a failure: the container starts, and the X server refuses its windows.
    """
    components = gui.host_display_components(project, host.name)
    if dry_run or not components:
        return []
    notes: list[str] = []
    for comp in components:
        display = gui.host_display(comp)
        argv = gui.host_cookie_argv(display, gui.host_cookie_folder(project, host, comp.name))
        result = _run(host, argv)
        who = "your user" if host.is_local else f"user {host.user} on {host.name}"
        if result == "no-xauth":
            notes.append(f"{comp.name}: xauth is not installed on {host.name}, so no X cookie: windows on {display} "
                         "will be refused (apt-get install xauth)")
        elif result == "no-cookie":
            notes.append(f"{comp.name}: no X cookie of {who} for display {display} (nobody logged in to it?): "
                         "its windows are refused until a run after a login")
    return notes


def _run(host: Host, argv: list[str]) -> str:
    """Run the cookie script on ``host``; its last output line."""
    if host.is_local:
        try:
            proc = subprocess.run(argv, capture_output=True, text=True, check=False, timeout=COOKIE_TIMEOUT)
        except subprocess.TimeoutExpired:
            raise HostError(f"host {host.name}: copying the X cookie timed out") from None
        if proc.returncode != 0:
            last = (proc.stderr.strip().splitlines() or ["no output"])[-1]
            raise HostError(f"host {host.name}: cannot copy the X cookie: {last}")
        output = proc.stdout
    else:
        from robocore.adapters import ssh

        output = ssh.run(host, argv, timeout=COOKIE_TIMEOUT).stdout.decode(errors="replace")
    lines = output.strip().splitlines()
    return lines[-1].split()[0] if lines else ""
