"""docs/performance.md is what bench/render_performance.py renders from bench/results/*.json, and the result files
are what bench/harness.py's ``record`` writes. (The bench scripts themselves measure speed; nothing here times.)"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RENDER = ROOT / "bench" / "render_performance.py"
RESULTS = ROOT / "bench" / "results"


def render(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(RENDER), *args], capture_output=True, text=True, timeout=60)


def test_the_page_is_current_with_the_result_files() -> None:
    done = render("--check")
    assert done.returncode == 0, done.stderr


def test_a_changed_result_file_makes_the_check_fail(tmp_path: Path) -> None:
    results = tmp_path / "results"
    shutil.copytree(RESULTS, results)
    assert render("--check", "--results", str(results)).returncode == 0  # the copy, unchanged, renders the page
    path = sorted(results.glob("*.json"))[0]
    run = json.loads(path.read_text())
    run["figures"][0]["value"] = 123456.0
    path.write_text(json.dumps(run))
    done = render("--check", "--results", str(results))
    assert done.returncode == 1
    assert "123,456" in done.stderr and "render_performance.py" in done.stderr


def test_a_bench_without_a_result_is_listed_as_not_yet_run(tmp_path: Path) -> None:
    page = tmp_path / "performance.md"
    done = render("--results", str(tmp_path / "none"), "--page", str(page))
    assert done.returncode == 0, done.stderr
    text = page.read_text()
    scripts = sorted(p.stem for p in (ROOT / "bench").glob("*.py")
                     if p.stem not in ("harness", "render_performance", "run_all", "chromium", "fleet_views"))
    assert "validate_scale" in scripts
    for name in scripts:
        assert f"Not yet run: `python bench/{name}.py`." in text


def test_record_writes_the_command_the_machine_and_the_figures(tmp_path: Path) -> None:
    script = tmp_path / "startup.py"  # stands in for bench/startup.py: record() checks the name is a bench script
    script.write_text('"""A trial bench."""\nfrom harness import Figure, record\n'
                      'record("startup", [Figure("a", 0.25, "s", "< 0.3 s", 0.5, "x bare", True, "d"), '
                      'Figure("b", "none")], goals=["g"], notes=["n"])\n')
    env = {**os.environ, "PYTHONPATH": str(ROOT / "bench"), "ROBOCORE_BENCH_RESULTS": str(tmp_path / "out")}
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    done = subprocess.run([sys.executable, str(script), "--runs", "3"], capture_output=True, text=True, env=env,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    run = json.loads((tmp_path / "out" / "startup.json").read_text())
    assert run["bench"] == "startup" and run["title"] == "A trial bench."
    assert run["command"].endswith("startup.py --runs 3") and run["command"].startswith("python ")
    assert run["date"].endswith("Z") and run["goals"] == ["g"] and run["notes"] == ["n"]
    machine = run["machine"]
    assert machine["cores"] == os.cpu_count() and machine["memory_gib"] > 0 and machine["python"]
    assert len(machine["load_at_start"]) == 3 and len(machine["load_at_end"]) == 3
    assert run["figures"] == [{"label": "a", "value": 0.25, "unit": "s", "goal": "< 0.3 s", "ratio": 0.5,
                               "ratio_of": "x bare", "met": True, "detail": "d"}, {"label": "b", "value": "none"}]
    assert not (RESULTS / ".startup.json.partial").exists()
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=60,
                          env={**env, "PYTHONDONTWRITEBYTECODE": "1"})  # start-up figures without bytecode
    assert done.returncode == 0, done.stderr
    assert json.loads((tmp_path / "out" / "startup.json").read_text())["notes"][1].startswith("PYTHONDONTWRITEBYTECODE")


def test_record_refuses_a_name_that_is_no_bench_script(tmp_path: Path) -> None:
    script = tmp_path / "x.py"
    script.write_text('from harness import record\nrecord("no_such_bench", [])\n')
    env = {**os.environ, "PYTHONPATH": str(ROOT / "bench"), "ROBOCORE_BENCH_RESULTS": str(tmp_path / "out")}
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=env, timeout=60)
    assert done.returncode != 0 and "no bench/no_such_bench.py" in done.stderr
    assert not (tmp_path / "out").exists()


def test_a_variants_result_gets_its_own_section_beside_the_benchs(tmp_path: Path) -> None:
    """A run of another distro (``<name>-<variant>.json``) is shown after the bench's own run, not instead of it."""
    results = tmp_path / "results"
    shutil.copytree(RESULTS, results)
    run = json.loads((results / "noop.json").read_text())
    run["figures"][0]["value"] = 654321.0
    (results / "noop-kilted.json").write_text(json.dumps({**run, "variant": "kilted"}))
    page = tmp_path / "performance.md"
    done = render("--results", str(results), "--page", str(page))
    assert done.returncode == 0, done.stderr
    text = page.read_text()
    assert text.index("## noop\n") < text.index("## noop-kilted\n") < text.index("## noop_young\n")
    assert "654,321" in text.split("## noop-kilted\n")[1].split("\n## ")[0]
    assert "[noop-kilted](#noop-kilted)" in text and "not yet run | | `python bench/noop-kilted.py`" not in text
