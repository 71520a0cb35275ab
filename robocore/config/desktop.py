"""GUI settings of robot.yaml: the VNC desktop a component can serve, and where ``gui`` windows go.

A component with ``desktop:`` runs robocore's VNC desktop (an X server with a VNC server built
in, a window manager, noVNC in a browser); ``gui: <that component>`` on another component of the
same host sends its windows there, and ``gui: true`` sends them to the host's own screen. X never
crosses hosts: a desktop on another host, or a ``DISPLAY`` that names another machine, is refused.
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Sequence
from typing import TYPE_CHECKING

from pydantic import Field

from robocore.config.hints import Unknown, known_list
from robocore.config.strict import Strict
from robocore.config.values import Number, shown

if TYPE_CHECKING:
    from robocore.config.model import Component

KeyPath = tuple[str | int, ...]
Found = tuple[KeyPath, str]

#: Debian (and Ubuntu) packages the desktop script needs: Xvnc, noVNC's web pages, websockify.
DESKTOP_PACKAGES = ("tigervnc-standalone-server", "novnc", "websockify")
#: The package of ``vncpasswd``, which turns the project's VNC password into Xvnc's password file
#: (a desktop without ``open: true``).
PASSWORD_PACKAGE = "tigervnc-tools"
#: The first VNC port; a desktop on display N serves VNC on ``VNC_BASE_PORT + N`` unless told otherwise.
VNC_BASE_PORT = 5900
SIZE = r"[1-9][0-9]{2,4}x[1-9][0-9]{2,4}"
_DISPLAY_RE = re.compile(r"^(?P<host>[^:]*):(?P<number>[0-9]+)(?:\.[0-9]+)?$")


class Desktop(Strict):
    """A VNC desktop served by the component: an X server that other components' windows draw into."""

    display: Number = Field(default=1, ge=1, le=63, description="X display number (:1); unique per host.")
    size: str = Field(default="1280x800", pattern=f"^{SIZE}$", description="Screen size, WIDTHxHEIGHT.")
    web_port: Number = Field(default=6080, ge=1, le=65535, description="Port of noVNC (http://<host>:PORT/vnc.html).")
    vnc_port: Number | None = Field(
        default=None, ge=1, le=65535, description="VNC port, on 127.0.0.1 only (default: 5900 + display)."
    )
    local_only: bool = Field(
        default=False, description="Serve noVNC on 127.0.0.1 only (reach it through ssh -L); "
        "otherwise on every interface.",
    )
    open: bool = Field(
        default=False, description="Serve the desktop without a password (validate warns); otherwise VNC asks "
        "for the project's password (`robocore desktop-password`).",
    )

    @property
    def rfb_port(self) -> int:
        """The VNC (RFB) port: ``vnc_port``, else 5900 + display."""
        return self.vnc_port if self.vnc_port is not None else VNC_BASE_PORT + self.display


def display_host(display: str) -> str | None:
    """The machine a ``DISPLAY`` value names (``laptop:0`` -> ``laptop``); ``""`` for this machine's
    sockets (``:0``, ``unix:0``); None when it is not a display at all."""
    match = _DISPLAY_RE.match(display.strip())
    if match is None:
        return None
    return "" if match["host"] in ("", "unix") else match["host"]


def package_name(entry: str) -> str:
    """The package of an ``apt_packages`` entry (``name``, ``name=version``, ``name/release``)."""
    return re.split(r"[=/]", entry, maxsplit=1)[0]


def gui_problems(components: Sequence[tuple[int, Component]]) -> Iterator[Found]:
    """Every problem of the ``desktop`` and ``gui`` settings, one ``(key path, message)`` each."""
    desktops = {c.name: c for _, c in components if c.desktop is not None}
    names = Unknown("component", [c.name for _, c in components])
    yield from _desktops(components)
    for index, comp in components:
        base: KeyPath = ("components", index)
        display = comp.environment.get("DISPLAY")
        if display is not None:
            host = display_host(display)
            if host is None and comp.gui is True:
                yield ((*base, "environment", "DISPLAY"),
                       f"{shown(display)} is not an X display of this host, such as ':0' or ':1'")
            elif host:
                yield ((*base, "environment", "DISPLAY"),
                       f"{shown(display)} sends X over the network to {shown(host)}, which robocore does not do; "
                       "use this host's own display (':0') or a desktop component on this host (gui: <name>)")
        if not isinstance(comp.gui, str):
            continue
        target = desktops.get(comp.gui)
        if target is None:
            if comp.gui not in names:
                yield (*base, "gui"), names.message(comp.gui)
            else:
                yield ((*base, "gui"),
                       f"{comp.gui!r} is not a desktop component (desktops: {known_list(desktops)}); "
                       "use gui: true for the host's own display")
        elif target.runs_on != comp.runs_on:
            yield ((*base, "gui"),
                   f"desktop {target.name!r} runs on {target.runs_on!r} and {comp.name} on {comp.runs_on!r}: X does "
                   f"not cross hosts; run {comp.name} on {target.runs_on!r}, or give {comp.runs_on!r} a desktop of "
                   "its own")
        elif display is not None:
            yield ((*base, "environment", "DISPLAY"),
                   f"gui: {comp.gui} sets DISPLAY to that desktop's display; remove DISPLAY from environment")


def _desktops(components: Sequence[tuple[int, Component]]) -> Iterator[Found]:
    taken: dict[tuple[str, str, int], int] = {}  # (host, what, number) -> component index
    for index, comp in components:
        desktop = comp.desktop
        if desktop is None:
            continue
        base: KeyPath = ("components", index)
        if comp.gui:
            yield (*base, "gui"), "a desktop component shows the windows of others; remove gui"
        for key in ("entrypoint", "launch_args"):
            if getattr(comp, key):
                yield (*base, key), "robocore starts the desktop (Xvnc, window manager, noVNC); remove it"
        if comp.image is None:
            have = {package_name(p) for p in comp.apt_packages}
            needed = DESKTOP_PACKAGES if desktop.open else (*DESKTOP_PACKAGES, PASSWORD_PACKAGE)
            missing = [p for p in needed if p not in have]
            if missing:
                yield ((*base, "apt_packages"),
                       f"a desktop needs {', '.join(needed)} (missing: {', '.join(missing)}); a window "
                       "manager such as openbox is optional"
                       + ("" if desktop.open else f"; {PASSWORD_PACKAGE} gives vncpasswd, for the desktop's password"))
        uses = (("display", "display", desktop.display), ("web_port", "port", desktop.web_port),
                ("vnc_port", "port", desktop.rfb_port))
        for key, what, number in uses:
            other = taken.get((comp.runs_on, what, number))
            if other is not None:
                yield ((*base, "desktop", key),
                       f"{what} {number} is already used by the desktop of components[{other}] on {comp.runs_on!r}")
            else:
                taken[(comp.runs_on, what, number)] = index
