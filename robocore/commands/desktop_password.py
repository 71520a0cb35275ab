"""desktop-password: the project's VNC password, which noVNC and VNC viewers ask for (made once, kept 0600 in
``.robocore/desktop/`` by :mod:`robocore.commands.support.displays`)."""

from __future__ import annotations

from robocore.commands.support.displays import ensure_desktop_password, valid_password
from robocore.errors import UsageError
from robocore.files import read_own_file
from robocore.project import Project


def desktop_password(project: Project) -> str:
    """The project's VNC password (made if it is not there yet), which noVNC and VNC viewers ask for."""
    path = ensure_desktop_password(project)
    if path is None:
        desktops = [c.name for c in project.robot.components if c.desktop is not None]
        raise UsageError("no desktop of this project asks for a password" +
                         (f" ({', '.join(desktops)}: desktop.open: true)" if desktops else " (no desktop component)"))
    password = valid_password(read_own_file(path))
    assert password is not None, "ensure_desktop_password just wrote it"
    return password
