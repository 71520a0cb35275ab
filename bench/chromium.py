"""Debian's headless Chromium driven by Selenium through Debian's chromedriver: the fleet page's browser tests and
its bench. Nothing is downloaded (Selenium Manager is told to stay offline); a missing browser or driver is an
error that says what to install, never a skip."""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

#: The Debian packages that hold the browser and its driver (scripts/bootstrap.sh installs them for the tests).
PACKAGES = ("chromium", "chromium-driver")


def binaries() -> tuple[str, str]:
    """The paths of ``chromium`` and ``chromedriver``; RuntimeError naming the packages when one is missing."""
    browser, driver = shutil.which("chromium"), shutil.which("chromedriver")
    if browser is None or driver is None:
        raise RuntimeError(f"the fleet page's browser tests need Debian's {' and '.join(PACKAGES)} "
                           f"(apt-get install -y {' '.join(PACKAGES)}): chromium={browser}, chromedriver={driver}")
    return browser, driver


@contextmanager
def chromium(width: int = 1280, height: int = 900) -> Iterator[Any]:
    """A headless Chromium WebDriver, quit when the block ends."""
    os.environ.setdefault("SE_OFFLINE", "true")  # Selenium Manager: never fetch a browser or a driver
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    browser, driver_path = binaries()
    options = webdriver.ChromeOptions()
    options.binary_location = browser
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                f"--window-size={width},{height}", "--no-first-run", "--disable-extensions"):
        options.add_argument(arg)
    driver = webdriver.Chrome(options=options, service=Service(executable_path=driver_path))
    try:
        yield driver
    finally:
        driver.quit()


#: The fleet page's row of one robot, read in one script (the live page may swap its rows in between two reads).
_ROW = """const tr = [...document.querySelectorAll('tr.robot')].find(t => t.dataset.robot === arguments[0]);
return tr ? ['name', 'state', 'release', 'gate', 'labels', 'graph']
              .map(c => tr.querySelector('td.' + c).innerText.trim())
          : null;"""


def fleet_row(driver: Any, robot: str) -> dict[str, str]:
    """``robot``'s cells (name, state, release, gate, labels, and the graph its last gate saw) as the fleet page in
    ``driver`` shows them; an empty dict when the page has no such row (not loaded yet)."""
    cells = driver.execute_script(_ROW, robot)
    return dict(zip(("name", "state", "release", "gate", "labels", "graph"), cells, strict=True)) if cells else {}


def graph_says(graph: str, release: str, nodes: set[str], heard: str) -> bool:
    """Whether a fleet page's graph cell (``fleet_row``'s ``graph``) says ``nodes`` (among others) were seen and only
    ``heard`` was heard, by a gate on ``release``."""
    seen, topics, when = [*graph.splitlines(), "", "", ""][:3]
    return (nodes <= set(seen.removeprefix("nodes: ").split(", ")) and topics == f"heard: {heard}"
            and when.startswith(f"on {release} at "))
