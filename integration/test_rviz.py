"""rviz kept working: the template's rviz recipe on a noetic robot (the debian base: Debian 12's own ROS 1 and its
rviz 1.14), drawing a marker that another component publishes through the ROS master, in software (Mesa's
llvmpipe: this machine has no GPU).

The project is ``robocore init --distro noetic --base debian``; its components are the template's commented
desktop and rviz examples, uncommented as a user would (the test moves the desktop to a free display and free
ports and leaves out the optional window manager), plus a ``marker`` component: ``rostopic pub`` of a magenta
cube (``visualization_msgs/Marker``, ``lifetime`` 1 s) at 5 Hz. The rviz config (a Marker display on
``/marker``) is the project's ``rviz/robot.rviz``, mounted read-only as the recipe says.

- in the desktop: a real RFB client's screenshot holds many magenta pixels while the marker is published;
  none once the publisher stops and the marker expires (the negative control), rviz still running; and the
  marker is back once the publisher is;
- on a screen (``gui: true``): the same rviz component moved to a real Xvfb of this machine (its
  ``DISPLAY``, the user's cookie copied by ``run``) draws the marker there, and the desktop no longer shows it;
  none again once the publisher stops.

The base image is shared with test_ros1_robot.py (same image_prefix, same inputs: built once); the desktop,
rviz and marker images are reused by content hash.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
import yaml
from deploy_helpers import free_tcp_port, log_lines, remove_project_containers, wait_for
from screens import RGB, VncRefused, count_colour, free_display, private_xvfb, vnc_screenshot, xvfb_screenshot

from robocore.plan import gui

if TYPE_CHECKING:
    from conftest import RobocoreCli

pytestmark = pytest.mark.docker

NAME = "robocore-it-rviz"
#: test_ros1_robot.py's prefix: the same noetic debian base (its inputs do not depend on the components).
IMAGE_PREFIX = "robocore-it-noetic-"
#: The marker: a 4 m magenta cube at the origin of the fixed frame, gone 1 s after the last message.
MARKER = ("{header: {frame_id: map}, ns: it, id: 1, type: 1, action: 0, pose: {orientation: {w: 1.0}}, "
          "scale: {x: 4.0, y: 4.0, z: 4.0}, color: {r: 1.0, g: 0.0, b: 1.0, a: 1.0}, lifetime: {secs: 1}}")
#: rviz 1.14's config: a Marker display of /marker in frame map, seen from 12 m, the side docks hidden.
RVIZ_CONFIG = """\
Panels: []
Visualization Manager:
  Class: ""
  Displays:
    - Class: rviz/Marker
      Enabled: true
      Marker Topic: /marker
      Name: Marker
      Namespaces: {}
      Queue Size: 100
      Value: true
  Enabled: true
  Global Options:
    Background Color: 48; 48; 48
    Default Light: true
    Fixed Frame: map
    Frame Rate: 30
  Name: root
  Tools: []
  Value: true
  Views:
    Current:
      Class: rviz/Orbit
      Distance: 12
      Focal Point: {X: 0, Y: 0, Z: 0}
      Name: Current View
      Pitch: 0.6
      Target Frame: <Fixed Frame>
      Value: Orbit (rviz)
      Yaw: 0.8
    Saved: ~
Window Geometry:
  Height: 700
  Width: 900
  X: 0
  Y: 0
  Hide Left Dock: true
  Hide Right Dock: true
"""
#: The cube's faces are lit, so shaded: a few hundred thousand pixels of one flat colour are not to be expected,
#: but far more than this many of a magenta hue are (the rest of rviz is grey).
SHOWN = 10_000
READY_WITHIN = 240.0


def magenta(colour: RGB) -> bool:
    """A magenta hue of any brightness: red and blue alike and well above green."""
    r, g, b = colour
    return min(r, b) >= 48 and g * 4 <= min(r, b) and abs(r - b) * 5 <= max(r, b)


def template_examples(text: str) -> dict[str, dict[str, Any]]:
    """The commented-out component examples of a generated robot.yaml, uncommented and parsed, by name: each
    block starts at a ``  # - name: ...`` line and ends at the first line that is not ``  # ...``."""
    found: dict[str, dict[str, Any]] = {}
    block: list[str] = []
    for line in [*text.splitlines(), ""]:
        if line.startswith("  # ") and (block or line.startswith("  # - name: ")):
            block.append(line[4:])
        elif block:
            found.update((c["name"], c) for c in yaml.safe_load("\n".join(block)))
            block = []
    return found


@pytest.fixture(scope="module")
def rviz_robot(docker_client: Any, run_robocore: RobocoreCli) -> Iterator[dict[str, Any]]:
    """The noetic project with the desktop, rviz and marker components, prepared, staged and running."""
    parent = Path(tempfile.mkdtemp(prefix="robocore-it-"))
    root = parent / NAME
    run_robocore(None, "init", str(root), "--defaults", "--distro", "noetic", "--base", "debian")
    data = yaml.safe_load((root / "robot.yaml").read_text())
    examples = template_examples((root / "robot.yaml").read_text())
    desktop, rviz = examples["desktop"], examples["rviz"]
    display, vnc_port, web_port = free_display()
    assert desktop["desktop"] == {} and "openbox" in desktop["apt_packages"]
    desktop["desktop"] = {"display": display, "web_port": web_port, "size": "1024x768"}
    desktop["apt_packages"].remove("openbox")  # optional; rviz's window opens at 0,0 without one
    assert rviz["gui"] == "desktop" and rviz["apt_packages"] == ["rviz"], rviz
    assert rviz["volumes"] == ["./rviz:/robocore/rviz:ro"] and rviz["environment"] == {"LIBGL_ALWAYS_SOFTWARE": "1"}
    marker = {"name": "marker", "runs_on": data["hosts"][0]["name"], "apt_packages": ["python3-visualization-msgs"],
              "entrypoint": f"rostopic pub -r 5 /marker visualization_msgs/Marker '{MARKER}'"}
    data.update(image_prefix=IMAGE_PREFIX, components=[desktop, rviz, marker],
                discovery={"servers": [{"host": data["hosts"][0]["name"], "port": free_tcp_port()}]})
    (root / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    (root / "rviz").mkdir()
    (root / "rviz" / "robot.rviz").write_text(RVIZ_CONFIG)
    try:
        run_robocore(root, "validate")
        for step in ("prepare-base", "stage", "run"):
            run_robocore(root, step, "--quiet")
        container = docker_client.containers.get(f"{NAME}-desktop")
        if not wait_for(lambda: log_lines(container, gui.DESKTOP_READY), READY_WITHIN):
            pytest.fail(f"the desktop did not get ready:\n{container.logs().decode(errors='replace')[-3000:]}",
                        pytrace=False)
        password = run_robocore(root, "desktop-password").stdout.strip()
        yield {"root": root, "vnc_port": vnc_port, "password": password}
    finally:
        remove_project_containers(docker_client, NAME)
        for volume in docker_client.volumes.list(filters={"name": f"{NAME}-"}):
            if volume.name == gui.desktop_volume(NAME, "desktop"):
                volume.remove(force=True)
        shutil.rmtree(parent, ignore_errors=True)


def _logs(docker_client: Any, component: str) -> str:
    return str(docker_client.containers.get(f"{NAME}-{component}").logs().decode(errors="replace")[-2500:])


def _until(count: Any, test: Any, timeout: float, what: str, docker_client: Any) -> int:
    """Poll ``count()`` until ``test(n)`` holds; the last count. Fails with the counts seen and rviz's log."""
    seen: list[int] = []

    def check() -> bool:
        # a VNC server that does not answer yet (the desktop still starting on a busy machine) is "not yet",
        # counted -1, which no test accepts
        try:
            seen.append(count())
        except VncRefused:
            seen.append(-1)
        return bool(test(seen[-1]))

    if not wait_for(check, timeout, interval=1):
        pytest.fail(f"{what} (magenta pixels, last counts: {seen[-6:]}); rviz log:\n"
                    f"{_logs(docker_client, 'rviz')}\nmarker log:\n{_logs(docker_client, 'marker')}", pytrace=False)
    return seen[-1]


def test_rviz_in_the_desktop_draws_the_marker_another_component_publishes(
        rviz_robot: dict[str, Any], docker_client: Any, tmp_path: Path) -> None:
    port, password = rviz_robot["vnc_port"], rviz_robot["password"]

    def on_desktop() -> int:
        image = vnc_screenshot(port, tmp_path / "desktop.png", password)
        assert image.size == (1024, 768)
        return count_colour(image, magenta)

    shown = _until(on_desktop, lambda n: n > SHOWN, READY_WITHIN, "no marker in rviz", docker_client)
    print(f"magenta pixels in the desktop with the marker published: {shown}")

    # control: the publisher stops; the marker expires (lifetime 1 s) and its colour is gone, rviz still running
    # (a client started before the desktop is up exits and is restarted: rviz may have restarted before)
    rviz = docker_client.containers.get(f"{NAME}-rviz")
    started = (rviz.attrs["RestartCount"], rviz.attrs["State"]["StartedAt"])
    publisher = docker_client.containers.get(f"{NAME}-marker")
    publisher.stop(timeout=5)
    try:
        stopped = time.monotonic()
        _until(on_desktop, lambda n: n == 0, 30, "the marker stayed after its publisher stopped", docker_client)
        print(f"no magenta pixel {time.monotonic() - stopped:.1f} s after the publisher stopped")
        rviz.reload()
        assert rviz.status == "running", rviz.attrs["State"]
        assert (rviz.attrs["RestartCount"], rviz.attrs["State"]["StartedAt"]) == started, rviz.attrs["State"]
    finally:
        publisher.start()
    _until(on_desktop, lambda n: n > SHOWN, 60, "the marker did not come back with its publisher", docker_client)


def test_rviz_with_gui_true_draws_the_marker_on_its_hosts_display(
        rviz_robot: dict[str, Any], docker_client: Any, run_robocore: RobocoreCli,
        tmp_path: Path) -> None:
    root = rviz_robot["root"]
    robot_yaml = root / "robot.yaml"
    original = robot_yaml.read_text()
    with private_xvfb(tmp_path) as screen:
        data = yaml.safe_load(original)
        rviz = next(c for c in data["components"] if c["name"] == "rviz")
        rviz.update(gui=True, environment={**rviz["environment"], "DISPLAY": screen.display})
        robot_yaml.write_text(yaml.safe_dump(data, sort_keys=False))
        try:
            run_robocore(root, "run", "--quiet", env={"XAUTHORITY": str(screen.auth)})

            def on_screen() -> int:
                return count_colour(xvfb_screenshot(screen.screen_folder), magenta)

            shown = _until(on_screen, lambda n: n > SHOWN, READY_WITHIN, f"no marker on {screen.display}",
                           docker_client)
            print(f"magenta pixels on the host's display with the marker published: {shown}")
            # rviz left the desktop: nothing magenta there
            desktop = vnc_screenshot(rviz_robot["vnc_port"], tmp_path / "desktop.png", rviz_robot["password"])
            assert count_colour(desktop, magenta) == 0
            # control: the publisher stops, the marker expires
            publisher = docker_client.containers.get(f"{NAME}-marker")
            publisher.stop(timeout=5)
            try:
                _until(on_screen, lambda n: n == 0, 30, "the marker stayed after its publisher stopped",
                       docker_client)
            finally:
                publisher.start()
        finally:
            robot_yaml.write_text(original)
            docker_client.containers.get(f"{NAME}-rviz").stop(timeout=5)  # its display goes with the Xvfb
