"""X11 access for dev containers: a per-container xauth cookie file, never ``xhost +``.

The developer's cookie for ``$DISPLAY`` (``xauth nlist``) is rewritten to the wildcard
address family (``ffff``), so it matches whatever host name the X client inside the container
reports, and merged into a file of its own (``xauth -f FILE nmerge -``) that is mounted into
the container with ``XAUTHORITY`` pointing at it. The X server keeps refusing everybody else.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

from robocore.errors import ToolMissing
from robocore.files import make_folder

#: The xauth family meaning "any address" (FamilyWild).
WILDCARD_FAMILY = "ffff"

_DISPLAY_RE = re.compile(r"^(?P<host>[^:]*):(?P<number>\d+)(?:\.\d+)?$")


def wildcard_entries(nlist: str) -> str:
    """``xauth nlist`` output with every entry's family replaced by the wildcard family."""
    out = []
    for line in nlist.splitlines():
        fields = line.split()
        if len(fields) < 2:
            continue
        out.append(" ".join([WILDCARD_FAMILY, *fields[1:]]))
    return "\n".join(out) + ("\n" if out else "")


def display_number(display: str) -> int | None:
    """The display number of ``$DISPLAY`` (``:1``, ``unix:1.0``, ``localhost:10.0``), None if unparsable."""
    match = _DISPLAY_RE.match(display.strip())
    return int(match["number"]) if match else None


def is_local_display(display: str) -> bool:
    """True when the display is reached through a socket in /tmp/.X11-unix (``:N``, ``unix:N``)."""
    match = _DISPLAY_RE.match(display.strip())
    return bool(match) and match is not None and match["host"] in ("", "unix")


def read_cookies(display: str, *, env: dict[str, str] | None = None) -> str:
    """``xauth nlist DISPLAY`` of the developer (``XAUTHORITY`` honoured); empty when there is none."""
    xauth = shutil.which("xauth")
    if xauth is None:
        raise ToolMissing("xauth is not installed: GUI programs in the shell cannot authenticate",
                          hint="install it (Debian/Ubuntu: apt-get install xauth)")
    proc = subprocess.run([xauth, "nlist", display], capture_output=True, text=True, env=env, check=False)
    return proc.stdout if proc.returncode == 0 else ""


def write_cookie_file(display: str, folder: Path, *, file_name: str = "xauth",
                      owner: tuple[int, int] | None = None, env: dict[str, str] | None = None) -> bool:
    """Write the wildcard cookie of ``display`` to ``folder/file_name``; False when there is no cookie.

    The file is built beside its final name and renamed over it, so a container that has the
    folder mounted sees either the old cookie or the new one. ``owner`` (uid, gid) is applied
    when it differs from the current user and the current user may change it (root).
    """
    entries = wildcard_entries(read_cookies(display, env=env))
    if not entries:
        return False
    make_folder(folder, private=True)  # a cookie is a secret: 0700 whatever the umask, never through a link
    if owner is not None and os.geteuid() == 0 and owner != (os.geteuid(), os.getegid()):
        os.chown(folder, owner[0], owner[1])
    xauth = shutil.which("xauth") or "xauth"
    fd, tmp = tempfile.mkstemp(prefix=f".{file_name}.", dir=folder)
    os.close(fd)
    try:
        proc = subprocess.run([xauth, "-q", "-f", tmp, "nmerge", "-"], input=entries, capture_output=True,
                              text=True, check=False)
        if proc.returncode != 0:
            return False
        os.chmod(tmp, 0o600)
        if owner is not None and os.geteuid() == 0 and owner != (os.geteuid(), os.getegid()):
            os.chown(tmp, owner[0], owner[1])
        os.replace(tmp, folder / file_name)
    finally:
        Path(tmp).unlink(missing_ok=True)
    return True
