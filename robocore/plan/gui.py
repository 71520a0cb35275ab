"""Where a deployed component's windows go, as data: environment, mounts and start order (pure).

Three cases, decided by robot.yaml:

* ``desktop:`` -- the component *is* a VNC desktop. It runs robocore's desktop script
  (``resources/desktop.sh``): TigerVNC's Xvnc on display ``:N``, a window manager, and noVNC
  through websockify. Its X socket folder ``/tmp/.X11-unix`` is a named volume of its own, and
  the script writes a fresh cookie (wildcard address family) beside the socket at every start.
  VNC asks for the project's password (``.robocore/desktop/vnc-password``, 0600): the file is
  bind-mounted read-only, never put in the environment or the compose file, and the script turns it
  into Xvnc's password file (``-SecurityTypes VncAuth``). ``desktop.open: true`` serves it without.
* ``gui: <desktop>`` -- the component draws into that desktop (same host; validate refuses
  another). It mounts the desktop's volume read-only at ``/tmp/.X11-unix``, so ``DISPLAY=:N``
  reaches the socket and ``XAUTHORITY`` the cookie, whatever its network. On host networking the
  X server's abstract socket is reachable too; it asks for the same cookie.
* ``gui: true`` -- the component draws on its host's own screen (``:0``, or the component's own
  ``DISPLAY``). It mounts the host's ``/tmp/.X11-unix`` and a folder holding a cookie of its own,
  which ``run`` makes before starting containers from the host user's Xauthority
  (:data:`HOST_COOKIE_SCRIPT`), as the dev shell does on the developer's machine.

X never crosses hosts, and the X servers never listen on TCP.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cache
from importlib import resources
from pathlib import Path, PurePosixPath

from robocore.config.model import Component, Host
from robocore.plan import naming
from robocore.plan.layout import CURRENT, component_root
from robocore.project import Project

#: Where X servers put their sockets, in every container.
X11_SOCKETS = "/tmp/.X11-unix"
#: The cookie a desktop writes beside its socket, read by its clients.
DESKTOP_XAUTHORITY = f"{X11_SOCKETS}/xauth"
#: Where a ``gui: true`` component finds its own cookie of the host's display.
HOST_COOKIE_MOUNT = "/robocore/x11"
COOKIE_FILE = "xauth"
#: The host's display when the component names none.
DEFAULT_DISPLAY = ":0"
#: Folder beside a remote component's releases that holds its cookie (``<mount_root>/<component>/...``).
REMOTE_COOKIE_FOLDER = ".robocore-x11"
#: The project's VNC password: the file in ``project.desktop_dir``, the folder of it in a remote release
#: (``<mount_root>/<component>/current/desktop/``), and where a desktop container reads it.
PASSWORD_FILE = "vnc-password"
PASSWORD_FOLDER = "desktop"
PASSWORD_MOUNT = "/run/robocore-desktop/vnc-password"
#: argv[0] of the desktop script, as ``ps`` and the logs show it.
DESKTOP_PROCESS = "robocore-desktop"
#: What the desktop script prints once the display and noVNC serve.
DESKTOP_READY = "robocore-desktop: display"

#: Run on a ``gui: true`` component's host (over ssh, or here for a local host) as the host user:
#: ``sh -c SCRIPT sh DISPLAY FOLDER``. Copies that user's cookie of DISPLAY, rewritten to the wildcard
#: address family, into FOLDER/xauth (made beside it, then renamed over it, so a running container sees
#: the old cookie or the new one). The Xauthority files looked at: $XAUTHORITY, ~/.Xauthority, and those
#: of GDM, GNOME's Xwayland and SDDM under /run/user/<uid>. Prints ``cookie FILE``, ``no-cookie`` or
#: ``no-xauth``; the folder exists afterwards in every case, so that the container's mount does.
HOST_COOKIE_SCRIPT = """\
set -eu
display=$1; folder=$2
mkdir -p -- "$folder"
chmod 0700 -- "$folder"
if ! command -v xauth >/dev/null 2>&1; then echo no-xauth; exit 0; fi
uid=$(id -u)
tmp=$(mktemp "$folder/.xauth.XXXXXX")
trap 'rm -f -- "$tmp"' EXIT
for file in "${XAUTHORITY:-}" "${HOME:-/nonexistent}/.Xauthority" "/run/user/$uid/gdm/Xauthority" \\
    /run/user/"$uid"/.mutter-Xwaylandauth.* /run/user/"$uid"/xauth_*; do
  [ -n "$file" ] && [ -f "$file" ] && [ -r "$file" ] || continue
  entries=$(xauth -f "$file" nlist "$display" 2>/dev/null) || continue
  [ -n "$entries" ] || continue
  printf '%s\\n' "$entries" | sed -e 's/^..../ffff/' | xauth -q -f "$tmp" nmerge - 2>/dev/null || continue
  chmod 0600 -- "$tmp"
  mv -f -- "$tmp" "$folder/xauth"
  echo "cookie $file"
  exit 0
done
echo no-cookie
"""


@dataclass(frozen=True)
class Bind:
    """A mount: a host path (absolute) or a named volume (bare name) at ``target``."""

    source: str
    target: str
    read_only: bool = False


@dataclass(frozen=True)
class GuiPlan:
    """What the display settings add to a component's container."""

    environment: dict[str, str] = field(default_factory=dict)
    binds: tuple[Bind, ...] = ()
    depends_on: tuple[str, ...] = ()  # services of the same host started first
    command: tuple[str, ...] | None = None  # replaces the component's command (a desktop)


@cache
def desktop_script() -> str:
    """The text of robocore's desktop script (run with ``bash -c``)."""
    return resources.files("robocore.resources").joinpath("desktop.sh").read_text(encoding="utf-8")


def desktop_volume(project_name: str, component: str) -> str:
    """The named volume of a desktop's X socket folder and cookie (one per desktop component)."""
    return f"{project_name}-{component}-x11"


def password_file(project: Project) -> Path:
    """The project's VNC password on this machine (0600 in a 0700 folder; see ``desktop_password``)."""
    return project.desktop_dir / PASSWORD_FILE


def needs_password(component: Component) -> bool:
    """Whether ``component`` is a desktop that asks for the project's VNC password (not ``open: true``)."""
    return component.desktop is not None and not component.desktop.open


def password_source(project: Project, host: Host, component: str) -> str:
    """The password file on ``host`` that desktop ``component`` mounts: the project's own for a local host; for a
    remote one, the copy ``sync`` ships in every release (``current/desktop/vnc-password``, mode kept: 0600)."""
    if host.is_local:
        return str(password_file(project))
    return str(component_root(host, component) / CURRENT / PASSWORD_FOLDER / PASSWORD_FILE)


def host_display(component: Component) -> str:
    """The display of a ``gui: true`` component on its host: its own ``DISPLAY``, else ``:0``."""
    return component.environment.get("DISPLAY", DEFAULT_DISPLAY)


def host_cookie_folder(project: Project, host: Host, component: str) -> str:
    """The folder on ``host`` that holds a ``gui: true`` component's cookie (mounted at :data:`HOST_COOKIE_MOUNT`)."""
    if host.is_local:
        return str(project.state_dir / "x11" / naming.container_name(project.name, component))
    return str(component_root(host, component) / REMOTE_COOKIE_FOLDER)


def host_cookie_argv(display: str, folder: str) -> list[str]:
    """argv that copies the host user's cookie of ``display`` into ``folder`` (see :data:`HOST_COOKIE_SCRIPT`)."""
    return ["sh", "-c", HOST_COOKIE_SCRIPT, "sh", display, folder]


def host_display_components(project: Project, host: str) -> list[Component]:
    """The components of ``host`` that draw on its own screen (``gui: true``)."""
    return [c for c in project.robot.components_on(host) if c.gui is True]


def gui_plan(project: Project, component: Component) -> GuiPlan:
    """The display part of ``component``'s container (empty when it shows no windows)."""
    if component.desktop is not None:
        return _desktop(project, component)
    if isinstance(component.gui, str):
        return _into_desktop(project, project.robot.component(component.gui))
    if component.gui:
        return _host_display(project, component)
    return GuiPlan()


def _desktop(project: Project, component: Component) -> GuiPlan:
    desktop = component.desktop
    assert desktop is not None
    env = {
        "ROBOCORE_DESKTOP_DISPLAY": str(desktop.display),
        "ROBOCORE_DESKTOP_SIZE": desktop.size,
        "ROBOCORE_DESKTOP_VNC_PORT": str(desktop.rfb_port),
        "ROBOCORE_DESKTOP_WEB_PORT": str(desktop.web_port),
        "ROBOCORE_DESKTOP_LISTEN": "127.0.0.1" if desktop.local_only else "0.0.0.0",
        "ROBOCORE_DESKTOP_XAUTHORITY": DESKTOP_XAUTHORITY,
        "ROBOCORE_DESKTOP_NAME": f"{project.name} {component.name}",
    }
    binds = [Bind(desktop_volume(project.name, component.name), X11_SOCKETS)]
    if not desktop.open:
        # the path of the secret, never the secret: env and compose files are shown by `docker inspect`
        env["ROBOCORE_DESKTOP_PASSWORD_FILE"] = PASSWORD_MOUNT
        host = project.robot.host(component.runs_on)
        binds.append(Bind(password_source(project, host, component.name), PASSWORD_MOUNT, read_only=True))
    return GuiPlan(
        environment=env,
        binds=tuple(binds),
        command=("bash", "-c", desktop_script(), DESKTOP_PROCESS),
    )


def _into_desktop(project: Project, desktop_component: Component) -> GuiPlan:
    desktop = desktop_component.desktop
    assert desktop is not None, "validate refuses gui: naming a component without desktop"
    env = {"DISPLAY": f":{desktop.display}", "XAUTHORITY": DESKTOP_XAUTHORITY, "QT_X11_NO_MITSHM": "1"}
    return GuiPlan(
        environment=env,
        binds=(Bind(desktop_volume(project.name, desktop_component.name), X11_SOCKETS, read_only=True),),
        depends_on=(desktop_component.name,),
    )


def _host_display(project: Project, component: Component) -> GuiPlan:
    host = project.robot.host(component.runs_on)
    env = {
        "DISPLAY": host_display(component),
        "XAUTHORITY": str(PurePosixPath(HOST_COOKIE_MOUNT) / COOKIE_FILE),
        "QT_X11_NO_MITSHM": "1",
    }
    return GuiPlan(
        environment=env,
        binds=(
            Bind(X11_SOCKETS, X11_SOCKETS, read_only=True),
            Bind(host_cookie_folder(project, host, component.name), HOST_COOKIE_MOUNT, read_only=True),
        ),
    )
