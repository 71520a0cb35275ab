"""The fleet page at fleet scale: 1000 robots rendered, and loaded in Debian's headless Chromium.

A synthetic look (bench/fleet_views.py's ``rollout_view``: v2 being rolled out, the canary and most robots healthy
on it, one robot being gated, one offline and pending; two components each and the graph each robot's last gate saw;
two releases) of N robots. Every robot is in the page; a wave of more
than ``FOLD_ABOVE`` (50) robots folds its healthy rows behind a button (robocore/plan/fleet_page.py says why):

1. **render**: ``render_page`` of the look, the first time (Jinja2 compiles the template) and then the median of
   :data:`RENDERS` renders: what ``fleet page --out`` and each look of ``--serve`` spend besides the manager's read;
2. **load**: the snapshot opened from ``file://`` in headless Chromium, the median of :data:`LOADS` navigations'
   ``loadEventEnd`` (Navigation Timing: parsing, style, layout of the whole page), and the first contentful paint;
3. **bytes**: the page, and the part the live page fetches again (``render_fleet``) when a look changed (an
   unchanged look costs a 304 with no body).

Goal: render and load each < 200 ms for 1000 robots.

    python bench/fleet_page.py [--robots 1000]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from chromium import chromium
from fleet_views import rollout_view
from harness import Figure, record

from robocore.plan.fleet_page import render_fleet, render_page

RENDERS = 20
LOADS = 7
GOAL_MS = 200.0
_TIMING = """const nav = performance.getEntriesByType('navigation')[0];
const paint = performance.getEntriesByName('first-contentful-paint')[0];
return [nav.loadEventEnd - nav.startTime, paint ? paint.startTime : null];"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=1000)
    args = parser.parse_args()
    view = rollout_view(args.robots)
    began = time.perf_counter()
    html = render_page(view)
    first_ms = (time.perf_counter() - began) * 1000
    times = []
    for _ in range(RENDERS):
        began = time.perf_counter()
        render_page(view)
        times.append((time.perf_counter() - began) * 1000)
    render_ms = statistics.median(times)
    part = render_fleet(view)
    with tempfile.TemporaryDirectory() as scratch, chromium() as browser:
        page = Path(scratch) / "index.html"
        page.write_text(html)
        loads, paints = [], []
        for _ in range(LOADS):
            browser.get("about:blank")
            browser.get(page.as_uri())
            load, paint = browser.execute_script(_TIMING)
            rows = browser.execute_script("return document.querySelectorAll('tr.robot').length")
            assert rows == args.robots, rows
            loads.append(float(load))
            if paint is not None:
                paints.append(float(paint))
    load_ms = statistics.median(loads)
    paint_ms = statistics.median(paints) if paints else None
    rows = [("render, first (template compiled)", first_ms, None), (f"render, median of {RENDERS}", render_ms, GOAL_MS),
            (f"load in headless Chromium, median of {LOADS}", load_ms, GOAL_MS)]
    if paint_ms is not None:
        rows.append(("first contentful paint", paint_ms, None))
    print(f"fleet page: {args.robots} robots, {len(html.encode()):,} bytes ({len(part.encode()):,} fetched again "
          "per changed look)")
    print(f"{'step':44} {'ms':>8}  {'goal':>8} {'ms/goal':>8}")
    for name, ms, goal in rows:
        print(f"{name:44} {ms:8.1f}  {f'< {goal:.0f}' if goal else '':>8} {f'{ms / goal:8.2f}' if goal else ''}")
    figures = [Figure(name, round(ms, 1), "ms", f"< {goal:.0f} ms" if goal else None,
                      round(ms / goal, 2) if goal else None, "ms / goal" if goal else "", ms < goal if goal else None)
               for name, ms, goal in rows]
    figures += [Figure("page", len(html.encode()), "bytes"), Figure("live part, per changed look", len(part.encode()),
                                                                   "bytes")]
    record("fleet_page", figures, goals=[f"render and load each < {GOAL_MS:.0f} ms for 1000 robots"],
           notes=[f"{args.robots} robots, synthetic look (bench/fleet_views.py); Chromium from Debian, headless",
                  "wall-clock figures: a busy machine (see the load average) inflates them"])


if __name__ == "__main__":
    main()
