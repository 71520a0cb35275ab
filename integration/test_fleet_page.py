"""The fleet page in a real browser: Debian's headless Chromium, driven by Selenium through Debian's chromedriver.

Synthetic looks (bench/fleet_views.py: two moments of one fleet, v2 being rolled out with one robot being gated and
one offline and pending, then v3's canary failed and back on v2), no Docker: the page as robocore renders it,
opened from ``file://`` (the snapshot) and from ``fleet page --serve``'s server (the live page, its look changed
under it). The real swarm's page is test_fleet_swarm.py's. Missing Chromium or chromedriver fails the module
(bench/chromium.py names the packages).
Screenshots go to the module's tmp folder (printed), and to ``$ROBOCORE_SCREENSHOTS`` when set.
"""

from __future__ import annotations

import os
import shutil
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from chromium import chromium, fleet_row
from fleet_views import CANARY_REASON, canary_failed_view, rollout_view

from robocore.adapters import page_server
from robocore.commands import fleet_page
from robocore.plan import gate_graph
from robocore.plan.fleet_page import FleetView, render_fleet, render_page

#: The page's red (the tone ``bad``), as the browser computes it.
RED = "rgba(207, 34, 46, 1)"


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    with chromium() as driver:
        yield driver


@pytest.fixture(scope="module")
def screens(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("fleet-page-screens")


def screenshot(browser: Any, screens: Path, name: str) -> Path:
    path = screens / f"{name}.png"
    assert browser.save_screenshot(str(path)), path
    print(f"screenshot: {path}")
    extra = os.environ.get("ROBOCORE_SCREENSHOTS")
    if extra:
        Path(extra).mkdir(parents=True, exist_ok=True)
        shutil.copy(path, Path(extra) / path.name)
    return path


def row(browser: Any, robot: str) -> Any:
    from selenium.webdriver.common.by import By

    found = [tr for tr in browser.find_elements(By.CSS_SELECTOR, "tr.robot") if tr.get_attribute("data-robot") == robot]
    assert len(found) == 1, (robot, len(found))
    return found[0]


def cell(tr: Any, name: str) -> str:
    from selenium.webdriver.common.by import By

    return str(tr.find_element(By.CSS_SELECTOR, f"td.{name}").text)


def test_the_snapshot_from_file_shows_every_robot_the_failed_canary_and_the_offline_one(
        browser: Any, screens: Path, tmp_path: Path) -> None:
    from selenium.webdriver.common.by import By

    view = canary_failed_view(6)
    page = fleet_page.write_snapshot(view, tmp_path / "snapshot")
    browser.get(page.as_uri())
    assert browser.title == "Fleet demo"
    for robot in view.robots:  # every robot, with its release and its health
        tr = row(browser, robot.robot)
        assert cell(tr, "release").startswith(f"runs {robot.running}"), cell(tr, "release")
        if robot.target != robot.running:
            assert f"target {robot.target}" in cell(tr, "release")
        assert cell(tr, "gate").startswith(robot.health or "deciding"), cell(tr, "gate")
    canary = row(browser, "r1")
    badge = canary.find_element(By.CSS_SELECTOR, "td.state .badge")
    assert badge.text == "✗ failed, back on v2"
    assert badge.value_of_css_property("color") == RED
    assert CANARY_REASON in cell(canary, "gate")
    assert cell(row(browser, "r6"), "state") == "○ offline, pending"
    assert cell(row(browser, "r3"), "state") == "✓ healthy"
    rollout = browser.find_element(By.ID, "rollout").text
    assert f"r1 (wave canary): failed, back on v2; reason: {CANARY_REASON}" in rollout
    assert "rollout stopped: 1 robot(s) failed the health gate" in rollout
    # the live ROS graph each robot's last gate saw, as text; none for the offline robot, whose gate ran no probe
    assert cell(row(browser, "r3"), "graph") == ("nodes: /listener, /talker\nheard: /chatter\n"
                                                 "on v2 at 2026-12-06T20:33:10Z")
    assert cell(row(browser, "r1"), "graph").endswith("on v2 at 2026-12-06T21:41:20Z")  # the way back's gate
    assert cell(row(browser, "r6"), "graph") == "no graph recorded"
    # nothing was fetched: no resource besides the document itself, and the page's policy allows none
    assert browser.execute_script("return performance.getEntriesByType('resource').length") == 0
    # the filter shows the robots of one label (a label is text on the page, not a query to anything)
    browser.find_element(By.ID, "filter").send_keys("site=depot")
    shown = [tr.get_attribute("data-robot") for tr in browser.find_elements(By.CSS_SELECTOR, "tr.robot")
             if tr.is_displayed()]
    assert shown == ["r2", "r4", "r6"], shown
    browser.find_element(By.ID, "filter").clear()
    browser.execute_script("document.getElementById('filter').dispatchEvent(new Event('input'))")
    screenshot(browser, screens, "fleet-page-snapshot")


HOSTILE = ['<script>window.pwned = "name"</script>', "it's \"quoted\"", "<img src=x onerror=\"window.pwned='img'\">"]


def test_a_script_or_quotes_in_a_name_or_label_is_shown_as_text(browser: Any, screens: Path, tmp_path: Path) -> None:
    from selenium.webdriver.common.by import By

    label = "<b onmouseover=\"window.pwned='label'\">lab</b>"
    view = canary_failed_view(names=[*HOSTILE, "r4"], site=label)
    robots = list(view.robots)  # a node name the probe printed is text as well
    robots[1] = replace(robots[1], seen=gate_graph.from_verdict({"nodes": [HOSTILE[2], "/talker"]}, "v2", "T"))
    view = replace(view, robots=tuple(robots))
    page = fleet_page.write_snapshot(view, tmp_path / "hostile")
    browser.get(page.as_uri())
    assert browser.execute_script("return window.pwned") is None
    assert browser.execute_script("return document.querySelectorAll('main script, main img, main b[onmouseover]')"
                                  ".length") == 0
    for name in HOSTILE:
        tr = row(browser, name)  # the attribute holds the very name, so the quotes did not end it
        assert cell(tr, "name") == name
    assert f"site={label}" in cell(row(browser, HOSTILE[0]), "labels")
    assert cell(row(browser, HOSTILE[1]), "graph").startswith(f"nodes: /talker, {HOSTILE[2]}\n")
    assert HOSTILE[0] in browser.find_element(By.ID, "rollout").text
    screenshot(browser, screens, "fleet-page-hostile")


class Moving:
    """A look that the test changes: what the server's :class:`fleet_page.Looks` reads."""

    def __init__(self, view: FleetView) -> None:
        self.view = view
        self.reads = 0

    def read(self) -> FleetView:
        self.reads += 1
        return self.view


def test_the_served_page_changes_without_a_reload_when_the_fleet_does(browser: Any, screens: Path) -> None:
    """v2's rollout in progress, then r2 passes its gate, then v3's canary fails and goes back to v2: the same
    document shows each look (state, the gate's reason, the graph the gate saw) without a reload."""
    from selenium.webdriver.common.by import By

    moving = Moving(rollout_view(6))
    looks = fleet_page.Looks(moving.read, every=0.0)
    server = page_server.start(page_server.Pages(page=lambda: render_page(looks.current(), live=True),
                                                 part=lambda: render_fleet(looks.current())), "127.0.0.1", 0)
    page_server.serve_in_thread(server)

    def shown(robot: str, key: str, value: str) -> bool:
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline and fleet_row(browser, robot).get(key) != value:
            time.sleep(0.25)  # read in one script: the page swaps its rows in meanwhile
        return fleet_row(browser, robot).get(key) == value

    try:
        browser.get(server.url)
        assert cell(row(browser, "r2"), "state").startswith("◔ being gated")
        assert cell(row(browser, "r2"), "graph") == "no graph recorded"
        assert cell(row(browser, "r1"), "state") == "✓ healthy"
        browser.execute_script("window.sameDocument = 42")  # gone if the page were loaded again
        screenshot(browser, screens, "fleet-page-live-before")
        reads = moving.reads
        time.sleep(5)  # unchanged looks: the page polls (304s) and stays as it was
        assert moving.reads > reads and fleet_row(browser, "r2")["state"].startswith("◔ being gated")
        # r2 passes its gate on v2: its probe saw the demo's graph
        robots = list(moving.view.robots)
        robots[1] = replace(robots[1], running="v2", health="healthy", state="online", components=robots[2].components,
                            seen=robots[2].seen)
        moving.view = replace(moving.view, robots=tuple(robots), taken="2026-12-06T20:33:30Z")
        assert shown("r2", "state", "✓ healthy"), fleet_row(browser, "r2")
        assert fleet_row(browser, "r2")["graph"].startswith("nodes: /listener, /talker\nheard: /chatter")
        assert "2026-12-06T20:33:30Z" in browser.find_element(By.CLASS_NAME, "taken").text
        # later, v3's canary fails its gate: red, with the gate's reason; then it is back on v2
        colour = "const b = document.querySelector(\"tr.robot[data-robot='r1'] .badge\");" \
                 " return b ? getComputedStyle(b).color : null;"
        moving.view = canary_failed_view(6, back=False)
        assert shown("r1", "state", "✗ failed"), fleet_row(browser, "r1")
        assert fleet_row(browser, "r1")["gate"] == f"failed: {CANARY_REASON}"
        assert fleet_row(browser, "r1")["release"] == "runs -, target v3"
        assert browser.execute_script(colour) == "rgb(207, 34, 46)"
        moving.view = canary_failed_view(6)
        assert shown("r1", "state", "✗ failed, back on v2"), fleet_row(browser, "r1")
        assert fleet_row(browser, "r1")["gate"] == f"rolled-back: {CANARY_REASON}"
        assert browser.execute_script(colour) == "rgb(207, 34, 46)"
        assert cell(row(browser, "r6"), "state") == "○ offline, pending"  # still cut off: still pending
        assert browser.execute_script("return window.sameDocument") == 42  # the same document: no reload
        screenshot(browser, screens, "fleet-page-live-after")
    finally:
        server.shutdown()
        server.server_close()


def test_a_big_wave_folds_its_healthy_robots_and_shows_them_on_demand(browser: Any, screens: Path,
                                                                      tmp_path: Path) -> None:
    """A wave of more than FOLD_ABOVE robots shows the ones that need a look; its healthy ones are one button away
    (and the filter finds them): what keeps a page of 1000 robots quick to load (bench/fleet_page.py)."""
    from selenium.webdriver.common.by import By

    view = rollout_view(80)
    browser.get(fleet_page.write_snapshot(view, tmp_path / "big").as_uri())

    def shown() -> list[str]:
        return [str(tr.get_attribute("data-robot")) for tr in browser.find_elements(By.CSS_SELECTOR, "tr.robot")
                if tr.is_displayed()]

    assert shown() == ["r1", "r2", "r80"]  # the failed canary, the robot being gated, the offline one
    button = browser.find_element(By.CSS_SELECTOR, "button.unfold")
    assert button.text == "✓ 77 healthy robot(s) of wave rest, folded: show them"
    button.click()
    assert shown() == [f"r{i}" for i in (1, 2, 80, *range(3, 80))]
    assert fleet_row(browser, "r42")["state"] == "✓ healthy"
    browser.find_element(By.CSS_SELECTOR, "button.unfold").click()  # folded again
    assert len(shown()) == 3
    browser.find_element(By.ID, "filter").send_keys("r42")  # the filter looks in the folded rows too
    assert shown() == ["r42"]
    screenshot(browser, screens, "fleet-page-folded")
