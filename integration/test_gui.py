"""GUI components on real containers: the template's VNC desktop example, staged on the demo project's wheels
base, with its X client drawing into it; checked with a real RFB client's screenshot and through noVNC.

The desktop and clock components are the commented-out block of the generated robot.yaml, uncommented
as a user would; the test only moves the desktop to a free display and free ports (a real X server or
another suite may use :1 and 6080 on this machine) and gives the clock a known background colour
(``launch_args``), so that its window can be counted in the screenshot. Controls: with the clock
stopped the colour is gone from the same desktop; an X client without the desktop's cookie is refused; an
RFB client without the project's VNC password, or with a wrong one, is refused, and the same desktop opened in
robot.yaml (``open: true``) serves one without.
The images (``robocore-it-demo-desktop``, ``-clock``) are kept as a cache, like the demo's.
"""

from __future__ import annotations

import random
import socket
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml
from deploy_helpers import copy_project, log_lines, remove_project_containers, wait_for
from screens import VncRefused, display_taken, free_display, vnc_screenshot

from robocore.plan import gui

pytestmark = pytest.mark.docker

#: xclock's background in the test: a colour nothing else on the desktop has.
MAGENTA = (255, 0, 255)
CLOCK_SIZE = (400, 300)
#: A window of CLOCK_SIZE minus its hands, ticks and border still has far more than this many pixels.
SHOWN = 80_000
READY_WITHIN = 120.0


def uncommented_desktop_example(text: str) -> list[dict[str, Any]]:
    """The commented-out desktop example of a generated robot.yaml, uncommented and parsed."""
    lines = text.splitlines()
    start = lines.index("  # - name: desktop")
    block = []
    for line in lines[start:]:
        if not line.startswith("  # "):
            break
        block.append(line[4:])
    components = yaml.safe_load("\n".join(block))
    assert [c["name"] for c in components] == ["desktop", "clock"]
    return list(components)


def rfb_security(port: int, choose: int) -> tuple[list[int], int | None]:
    """An RFB 3.8 handshake by hand: the security types the server offers, and its security result when the
    client picks ``choose`` (1: None) anyway: 0 is OK, anything else a failure, None when it hung up."""
    with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
        reader = sock.makefile("rb")
        assert reader.read(12).startswith(b"RFB 003.008")
        sock.sendall(b"RFB 003.008\n")
        count = reader.read(1)[0]
        types = list(reader.read(count))
        if not count:
            return [], None
        sock.sendall(bytes([choose]))
        result = reader.read(4)
        return types, int.from_bytes(result, "big") if len(result) == 4 else None


def magenta_pixels(vnc_port: int, shot: Path, password: str | None,
                   timeout: float = 30) -> tuple[int, tuple[int, int]]:
    """Screenshot the desktop through VNC (vncdotool, a real RFB client, with the VNC password if one is given);
    the count of MAGENTA pixels and the size."""
    image = vnc_screenshot(vnc_port, shot, password, timeout)
    colours = image.getcolors(maxcolors=image.width * image.height) or []
    return sum(count for count, colour in colours if colour == MAGENTA), image.size


@pytest.fixture(scope="module")
def desktop_robot(demo_project: Path, tmp_path_factory: pytest.TempPathFactory, docker_client: Any,
                  run_robocore: Any) -> Iterator[dict[str, Any]]:
    """A copy of the demo project whose components are the template's desktop example, staged and running."""
    name = f"robocore-it-gui-{int(time.time()) % 100000}"
    display, vnc_port, web_port = free_display()
    example = uncommented_desktop_example((demo_project / "robot.yaml").read_text())

    def edit(data: dict[str, Any]) -> None:
        desktop, clock = example
        assert desktop["desktop"] == {} and clock["gui"] == "desktop"
        desktop["desktop"] = {"display": display, "web_port": web_port, "size": "1024x768"}
        clock["launch_args"] = f"-bg '#ff00ff' -geometry {CLOCK_SIZE[0]}x{CLOCK_SIZE[1]}+20+40"
        data["components"] = example

    root = copy_project(demo_project, tmp_path_factory.mktemp("gui"), name, edit=edit)
    try:
        run_robocore(root, "validate")
        run_robocore(root, "stage", "--quiet", timeout=1200)
        run_robocore(root, "run", "--quiet")
        desktop = docker_client.containers.get(f"{name}-desktop")
        if not wait_for(lambda: log_lines(desktop, gui.DESKTOP_READY), READY_WITHIN):
            pytest.fail(f"the desktop did not get ready:\n{desktop.logs().decode(errors='replace')[-3000:]}",
                        pytrace=False)
        password = run_robocore(root, "desktop-password").stdout.strip()
        yield {"root": root, "name": name, "display": display, "vnc_port": vnc_port, "web_port": web_port,
               "password": password}
    finally:
        remove_project_containers(docker_client, name)
        for volume in docker_client.volumes.list(filters={"name": f"{name}-"}):
            if volume.name == gui.desktop_volume(name, "desktop"):
                volume.remove(force=True)


def test_the_desktop_shows_the_window_of_another_containers_x_client(desktop_robot: dict[str, Any],
                                                                       docker_client: Any, tmp_path: Path) -> None:
    port, password = desktop_robot["vnc_port"], desktop_robot["password"]
    clock = docker_client.containers.get(f"{desktop_robot['name']}-clock")

    counts: list[int] = []

    def window_shown() -> bool:
        count, size = magenta_pixels(port, tmp_path / "with-clock.png", password)
        assert size == (1024, 768)
        counts.append(count)
        return count > SHOWN

    if not wait_for(window_shown, READY_WITHIN, interval=2):
        pytest.fail(f"no clock window on the desktop (magenta pixels: {counts[-5:]}); clock log:\n"
                    f"{clock.logs().decode(errors='replace')[-2000:]}", pytrace=False)
    shown = counts[-1]
    assert shown <= CLOCK_SIZE[0] * CLOCK_SIZE[1]  # the window's own pixels, nothing else is magenta
    print(f"magenta pixels with the clock running: {shown}")

    # control: the same desktop without the client has no magenta at all
    clock.stop(timeout=5)
    try:
        gone: list[int] = []

        def window_gone() -> bool:
            gone.append(magenta_pixels(port, tmp_path / "without-clock.png", password)[0])
            return gone[-1] == 0

        assert wait_for(window_gone, 30, interval=1), f"magenta still shown without the clock: {gone[-5:]}"
        print(f"magenta pixels with the clock stopped: {gone[-1]}")
    finally:
        clock.start()


def test_an_x_client_without_the_desktops_cookie_is_refused(desktop_robot: dict[str, Any], docker_client: Any) -> None:
    clock = docker_client.containers.get(f"{desktop_robot['name']}-clock")
    assert wait_for(lambda: clock.reload() or clock.status == "running", 30)
    display = f":{desktop_robot['display']}"
    env = clock.attrs["Config"]["Env"]
    assert f"DISPLAY={display}" in env and f"XAUTHORITY={gui.DESKTOP_XAUTHORITY}" in env
    with_cookie = clock.exec_run(["timeout", "2", "xclock"], environment={"DISPLAY": display})
    assert with_cookie.exit_code == 124, with_cookie.output  # opened the display, ran until timeout stopped it
    without = clock.exec_run(["timeout", "2", "xclock"], environment={"DISPLAY": display, "XAUTHORITY": "/dev/null"})
    assert without.exit_code == 1 and b"Authorization required" in without.output, without.output


def test_novnc_serves_its_page_and_reaches_the_vnc_server(desktop_robot: dict[str, Any]) -> None:
    import websocket

    web = desktop_robot["web_port"]
    with urllib.request.urlopen(f"http://127.0.0.1:{web}/vnc.html", timeout=10) as page:
        assert page.status == 200 and b"noVNC" in page.read()
    conn = websocket.create_connection(f"ws://127.0.0.1:{web}/websockify", timeout=10, subprotocols=["binary"])
    try:
        banner = conn.recv()
    finally:
        conn.close()
    assert bytes(banner if isinstance(banner, bytes) else banner.encode()).startswith(b"RFB 003.008")


def test_the_desktop_asks_for_the_projects_password_and_refuses_a_client_without_it(
        desktop_robot: dict[str, Any], docker_client: Any, tmp_path: Path) -> None:
    import stat

    port, password = desktop_robot["vnc_port"], desktop_robot["password"]
    secret = desktop_robot["root"] / ".robocore" / "desktop" / "vnc-password"
    assert secret.read_text() == password and len(password) == 8
    assert stat.S_IMODE(secret.stat().st_mode) == 0o600 and stat.S_IMODE(secret.parent.stat().st_mode) == 0o700
    # the container holds the path of the secret, never the secret (docker inspect shows env and command)
    desktop = docker_client.containers.get(f"{desktop_robot['name']}-desktop")
    assert password not in str(desktop.attrs["Config"]) and password not in str(desktop.attrs["Args"])
    assert log_lines(desktop, "VNC security: VncAuth")
    # a client that skips authentication: offered VNC authentication only, and refused when it asks for none
    types, result = rfb_security(port, choose=1)
    assert types == [2], types
    assert result != 0, result  # no "OK" security result: failed, or hung up
    # a real RFB client with a wrong password is refused; with the project's password it gets the screen
    with pytest.raises(VncRefused):
        magenta_pixels(port, tmp_path / "wrong.png", "wrong123", timeout=10)
    assert not (tmp_path / "wrong.png").exists()
    assert wait_for(lambda: log_lines(desktop, "Authentication failure"), 10), \
        desktop.logs().decode(errors="replace")[-2000:]  # Xvnc's own word: refused for the password
    assert magenta_pixels(port, tmp_path / "right.png", password)[1] == (1024, 768)


def test_a_desktop_opened_in_robot_yaml_serves_a_client_without_a_password(
        desktop_robot: dict[str, Any], docker_client: Any, run_robocore: Any,
        tmp_path: Path) -> None:
    root, port = desktop_robot["root"], desktop_robot["vnc_port"]
    robot_yaml = root / "robot.yaml"
    original = robot_yaml.read_text()
    data = yaml.safe_load(original)
    data["components"][0]["desktop"]["open"] = True
    robot_yaml.write_text(yaml.safe_dump(data, sort_keys=False))
    desktop_name = f"{desktop_robot['name']}-desktop"
    try:
        checked = run_robocore(root, "validate")
        assert "desktop.open: warning:" in checked.stdout + checked.stderr and "without a password" in \
            checked.stdout + checked.stderr
        run_robocore(root, "run", "--quiet")
        desktop = docker_client.containers.get(desktop_name)
        assert "ROBOCORE_DESKTOP_PASSWORD_FILE" not in str(desktop.attrs["Config"]["Env"])
        assert wait_for(lambda: log_lines(desktop, "VNC security: None"), READY_WITHIN), \
            desktop.logs().decode(errors="replace")[-2000:]
        assert rfb_security(port, choose=1) == ([1], 0)
        assert magenta_pixels(port, tmp_path / "open.png", None)[1] == (1024, 768)
    finally:  # back to the password, for the tests after this one
        robot_yaml.write_text(original)
        run_robocore(root, "run", "--quiet")
        desktop = docker_client.containers.get(desktop_name)
        wait_for(lambda: log_lines(desktop, "VNC security: VncAuth"), READY_WITHIN)


# --------------------------------------------------------------------------- gui: true, the host's own display


@pytest.fixture
def host_display(tmp_path: Path) -> Iterator[tuple[str, Path]]:
    """A real Xvfb on this machine that accepts only clients holding its cookie; (DISPLAY, its Xauthority)."""
    import secrets
    import subprocess

    number = next(n for n in random.sample(range(64, 200), 136) if not display_taken(n))
    auth = tmp_path / "login.xauth"
    subprocess.run(["xauth", "-q", "-f", str(auth), "add", f":{number}", ".", secrets.token_hex(16)], check=True)
    server = subprocess.Popen(["Xvfb", f":{number}", "-auth", str(auth), "-nolisten", "tcp", "-screen", "0",
                               "800x600x24"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    if not wait_for(lambda: Path(f"/tmp/.X11-unix/X{number}").exists() or server.poll() is not None, 20) or \
            server.poll() is not None:
        server.kill()
        pytest.fail(f"Xvfb :{number} did not start", pytrace=False)
    try:
        yield f":{number}", auth
    finally:
        server.terminate()
        server.wait(timeout=10)


def _windows(display: str, auth: Path) -> str:
    import subprocess

    done = subprocess.run(["xwininfo", "-root", "-tree", "-display", display], capture_output=True, text=True,
                          env={"PATH": "/usr/bin:/bin", "XAUTHORITY": str(auth)}, timeout=20)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_a_gui_true_component_draws_on_its_hosts_display_with_the_users_cookie(
        desktop_robot: dict[str, Any], demo_project: Path, host_display: tuple[str, Path], tmp_path: Path,
        docker_client: Any, run_robocore: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    import json

    display, auth = host_display
    name = f"robocore-it-hostx-{int(time.time()) % 100000}"
    example = uncommented_desktop_example((demo_project / "robot.yaml").read_text())

    def edit(data: dict[str, Any]) -> None:
        clock = example[1]
        clock.update(gui=True, environment={"DISPLAY": display}, launch_args="-geometry 300x200+10+10")
        data["components"] = [clock]

    root = copy_project(demo_project, tmp_path, name, edit=edit)
    empty_home = tmp_path / "home"
    empty_home.mkdir()
    monkeypatch.setenv("HOME", str(empty_home))
    try:
        run_robocore(root, "stage", "--quiet", timeout=1200)  # the desktop suite's clock image: nothing to do
        # control first: nobody's cookie for that display (no XAUTHORITY, an empty home) -> refused, and said
        monkeypatch.delenv("XAUTHORITY", raising=False)
        (result,) = json.loads(run_robocore(root, "run", "--json").stdout)["results"]
        assert any(f"no X cookie of your user for display {display}" in note for note in result["notes"])
        clock = docker_client.containers.get(f"{name}-clock")
        refused = wait_for(lambda: b"Authorization required" in clock.logs(), 30)
        assert refused, clock.logs().decode(errors="replace")[-2000:]
        assert '"xclock"' not in _windows(display, auth)

        # the user's session cookie: the next run copies it, and the running container's client gets in
        monkeypatch.setenv("XAUTHORITY", str(auth))
        (result,) = json.loads(run_robocore(root, "run", "--json").stdout)["results"]
        assert result["notes"] == [] and {a["verb"] for a in result["actions"]} <= {"keep", "start"}
        shown = wait_for(lambda: '"xclock"' in _windows(display, auth), 120, interval=2)
        assert shown, f"no xclock window on {display}:\n{_windows(display, auth)}\n" + \
            clock.logs().decode(errors="replace")[-1000:]
        assert "300x200+10+10" in next(line for line in _windows(display, auth).splitlines() if '"xclock"' in line)
    finally:
        remove_project_containers(docker_client, name)
