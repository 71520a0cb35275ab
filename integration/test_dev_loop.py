"""`robocore dev` on this machine's Docker: a save is deployed and heard; a save that breaks the build deploys
nothing (the robot keeps the last good code, one line says why) and the loop goes on to deploy the fix.

Controls: container IDs (a recreated container has a new ID): the talker is recreated for a good save and left
alone for the broken one; the listener keeps hearing the last good text while the build is broken.
"""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
from deploy_helpers import HEARD, log_lines, wait_for

if TYPE_CHECKING:
    from conftest import RobocoreCli

pytestmark = pytest.mark.docker

HEAR_WITHIN = 120.0


class Dev:
    """``robocore dev --component talker --quiet`` in the background, its output kept."""

    def __init__(self, root: Path) -> None:
        self.lines: list[str] = []
        self.proc = subprocess.Popen([sys.executable, "-m", "robocore", "-p", str(root), "dev", "--component",
                                      "talker", "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))

    def said(self, start: str) -> list[str]:
        return [line for line in self.lines if line.startswith(start)]

    def stop(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            self.proc.kill()


def test_dev_deploys_each_save_and_a_broken_build_deploys_nothing(
        project_copies: Callable[..., Path], docker_client: Any, run_robocore: RobocoreCli) -> None:
    root = project_copies("dev")
    run_robocore(root, "run", "--quiet")
    listener = docker_client.containers.get(f"{root.name}-listener")
    assert wait_for(lambda: log_lines(listener, HEARD), HEAR_WITHIN), "the listener heard nothing after run"
    package = root / "components" / "talker" / "src" / "demo_talker"
    code = package / "demo_talker" / "talker.py"
    setup = package / "setup.py"
    text, setup_text = code.read_text(), setup.read_text()
    dev = Dev(root)
    try:
        assert wait_for(lambda: dev.said("dev: watching"), 300), "\n".join(dev.lines)
        talker_before = docker_client.containers.get(f"{root.name}-talker").id
        code.write_text(text.replace('f"hello from talker #', 'f"saved talker #'))
        assert wait_for(lambda: log_lines(listener, "saved talker #"), HEAR_WITHIN), "\n".join(dev.lines)
        talker_good = docker_client.containers.get(f"{root.name}-talker").id
        assert talker_good != talker_before  # the save was deployed by recreating the talker
        # a save that breaks the build: colcon fails; nothing is synced or restarted
        deployed = len(dev.said("dev: deployed"))
        setup.write_text(setup_text + "\nraise SystemExit('broken on purpose')\n")
        code.write_text(text.replace('f"hello from talker #', 'f"never heard #'))
        assert wait_for(lambda: dev.said("dev: build failed"), 300), "\n".join(dev.lines)
        for line in dev.said("dev: build failed"):
            assert line.endswith("(the robot keeps running the last good release; watching for the next save)"), line
        assert len(dev.said("dev: deployed")) == deployed
        assert docker_client.containers.get(f"{root.name}-talker").id == talker_good
        since = time.time()
        assert wait_for(lambda: log_lines(listener, "saved talker #", since=since), HEAR_WITHIN)
        assert not log_lines(listener, "never heard #")
        # the fix is deployed by the same loop
        setup.write_text(setup_text)
        code.write_text(text.replace('f"hello from talker #', 'f"fixed talker #'))
        assert wait_for(lambda: log_lines(listener, "fixed talker #"), HEAR_WITHIN), "\n".join(dev.lines)
        assert dev.proc.poll() is None  # still watching
    finally:
        dev.stop()
