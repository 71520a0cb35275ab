"""Screens for the GUI suites: free X displays and ports, a private Xvfb, and screenshots of both kinds of
screen robocore draws on (a desktop component's VNC server, a host's own X display), counted by colour.

- :func:`free_display`: an X display number no server uses here, its VNC port (5900 + N) and a free web port;
- :func:`vnc_screenshot`: a real RFB client's screenshot (vncdotool) of a desktop component;
- :func:`private_xvfb`: an Xvfb that accepts only clients holding its cookie, its screen kept in an XWD file
  (``-fbdir``) that :func:`xvfb_screenshot` reads, so no X client is needed to look at it;
- :func:`count_colour`: how many pixels of an image are of one hue (lit 3D surfaces are shaded: a flat colour
  count would miss them).
"""

from __future__ import annotations

import random
import secrets
import socket
import struct
import subprocess
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import lanes
from deploy_helpers import wait_for

RGB = tuple[int, int, int]


def display_taken(number: int) -> bool:
    """Whether an X server (socket, lock file or abstract socket) holds display ``number`` on this machine."""
    if Path(f"/tmp/.X11-unix/X{number}").exists() or Path(f"/tmp/.X{number}-lock").exists():
        return True
    abstract = f"@/tmp/.X11-unix/X{number}"
    return any(line.split()[-1] == abstract for line in Path("/proc/net/unix").read_text().splitlines()[1:]
               if line.split())


def tcp_free(port: int) -> bool:
    """Whether TCP ``port`` can be bound on every interface right now."""
    with socket.socket() as sock:
        try:
            sock.bind(("0.0.0.0", port))
        except OSError:
            return False
    return True


def free_display(numbers: range | None = None) -> tuple[int, int, int]:
    """A display number no X server uses here (of this lane's share of 20-63: two lanes never race for one),
    with its free VNC port (5900 + N) and a free web port."""
    numbers = numbers or lanes.share(20, 63)
    for number in random.sample(numbers, len(numbers)):
        if display_taken(number) or not tcp_free(5900 + number):
            continue
        for _ in range(100):
            web = random.choice(lanes.ports())
            if tcp_free(web):
                return number, 5900 + number, web
    raise RuntimeError("no free X display and ports")


class VncRefused(Exception):
    """The VNC client got no screen: the server refused it, hung up or did not answer in time."""


# vncdotool runs a Twisted reactor in a thread, and a reactor stopped once cannot start again in that process:
# two suites that each shut it down at their end leave the second one with a client that never connects. Each
# screenshot is therefore taken by a short-lived Python process of its own (the password goes on its stdin).
_CAPTURE = """
import sys
from vncdotool import api
port, shot, timeout = sys.argv[2], sys.argv[3], float(sys.argv[4])  # argv[1] is "--"
password = sys.stdin.read() or None
client = api.connect("127.0.0.1::" + port, password=password, timeout=timeout)
try:
    client.captureScreen(shot)
finally:
    try:
        client.disconnect()
    finally:
        api.shutdown()
"""


def vnc_screenshot(vnc_port: int, shot: Path, password: str | None, timeout: float = 30) -> Any:
    """The desktop on ``vnc_port`` (127.0.0.1) as an RGB PIL image, through vncdotool (a real RFB client, with the
    VNC password if one is given), run in a process of its own; also saved to ``shot``. Raises
    :class:`VncRefused` when no screen came back (refused, hung up, or nothing within ``timeout``)."""
    from PIL import Image

    try:
        done = subprocess.run([sys.executable, "-c", _CAPTURE, "--", str(vnc_port), str(shot), str(timeout)],
                              input=password or "", capture_output=True, text=True, timeout=timeout + 30)
    except subprocess.TimeoutExpired as error:
        raise VncRefused(f"no screen from VNC port {vnc_port} within {timeout + 30:.0f} s") from error
    if done.returncode != 0 or not shot.exists():
        raise VncRefused(f"no screen from VNC port {vnc_port}: {done.stderr.strip()[-500:]}")
    return Image.open(shot).convert("RGB")


@dataclass(frozen=True)
class XDisplay:
    """A private X server: its ``DISPLAY``, the Xauthority file holding its cookie, the folder of its screen."""

    display: str
    auth: Path
    screen_folder: Path


@contextmanager
def private_xvfb(folder: Path, size: str = "1024x768") -> Iterator[XDisplay]:
    """A real Xvfb on a free display of this machine, with GLX (Mesa draws for its clients), that accepts only
    clients holding its cookie (in ``folder/login.xauth``); its screen is the XWD file ``Xvfb_screen0`` in
    ``folder/screen``. Stopped at the end."""
    number = next(n for n in random.sample(range(64, 200), 136) if not display_taken(n))
    auth = folder / "login.xauth"
    screen = folder / "screen"
    screen.mkdir(parents=True, exist_ok=True)
    auth.touch(mode=0o600)
    subprocess.run(["xauth", "-q", "-f", str(auth), "add", f":{number}", ".", secrets.token_hex(16)], check=True)
    server = subprocess.Popen(["Xvfb", f":{number}", "-auth", str(auth), "-nolisten", "tcp", "-screen", "0",
                               f"{size}x24", "-fbdir", str(screen)], stdout=subprocess.DEVNULL,
                              stderr=subprocess.PIPE)
    try:
        up = wait_for(lambda: Path(f"/tmp/.X11-unix/X{number}").exists() or server.poll() is not None, 20)
        if not up or server.poll() is not None:
            raise RuntimeError(f"Xvfb :{number} did not start")
        yield XDisplay(f":{number}", auth, screen)
    finally:
        server.terminate()
        try:
            server.wait(timeout=10)
        except subprocess.TimeoutExpired:
            server.kill()
            server.wait(timeout=10)
        if server.stderr is not None:
            server.stderr.close()


def xvfb_screenshot(screen_folder: Path) -> Any:
    """The screen of an Xvfb started with ``-fbdir`` as an RGB PIL image: its ``Xvfb_screen0`` is an XWD file
    (a big-endian header of 25 numbers, the window name, a colour map, then the rows of pixels)."""
    from PIL import Image

    data = (screen_folder / "Xvfb_screen0").read_bytes()
    fields = struct.unpack(">25I", data[:100])
    header_size, width, height = fields[0], fields[4], fields[5]
    byte_order, bits_per_pixel, bytes_per_line, ncolors = fields[7], fields[11], fields[12], fields[19]
    if bits_per_pixel != 32:
        raise ValueError(f"an XWD screen of {bits_per_pixel} bits per pixel (expected 32, depth 24)")
    start = header_size + 12 * ncolors
    raw = "BGRX" if byte_order == 0 else "XRGB"  # LSBFirst: blue is the lowest byte
    return Image.frombuffer("RGB", (width, height), data[start:start + bytes_per_line * height], "raw", raw,
                            bytes_per_line, 1)


def count_colour(image: Any, hue: Callable[[RGB], bool]) -> int:
    """How many pixels of ``image`` (RGB) ``hue`` accepts."""
    colours = image.getcolors(maxcolors=image.width * image.height) or []
    return sum(count for count, colour in colours if hue(colour))
