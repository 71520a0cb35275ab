"""The images' entrypoint (resources/entrypoint.sh) run by bash in a fake root: what colcon's setup scripts see."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path, PurePosixPath

from robocore import resources
from robocore.plan import naming

#: What the fake install tree's local_setup.bash records: the interpreter colcon would run its helper with,
#: and that interpreter's own flags (isolated, no site) when it runs.
LOCAL_SETUP = """\
echo "helper=${COLCON_PYTHON_EXECUTABLE:-none}" >> "$ROBOCORE_TEST_LOG"
if [ -n "${COLCON_PYTHON_EXECUTABLE:-}" ]; then
    "$COLCON_PYTHON_EXECUTABLE" -c 'import sys; print("flags", sys.flags.isolated, sys.flags.no_site)' \
        >> "$ROBOCORE_TEST_LOG"
fi
"""


def _fake_root(tmp_path: Path) -> tuple[Path, Path]:
    """A root with the entrypoint, setup-python, an empty ROS setup.bash and an install tree; (entrypoint, log)."""
    root = tmp_path / "root"
    (root / "opt/ros/jazzy").mkdir(parents=True)
    (root / "opt/ros/jazzy/setup.bash").write_text("")
    (root / "robocore/install").mkdir(parents=True)
    (root / "robocore/install/local_setup.bash").write_text(LOCAL_SETUP)
    text = resources.read("entrypoint.sh").decode()
    for prefix in ("/opt/ros/", "/opt/robocore/", "/robocore/"):
        text = text.replace(prefix, f"{root}{prefix}")
    entrypoint = root / "robocore/entrypoint.sh"
    entrypoint.write_text(text)
    helper = root / "robocore/setup-python"
    helper.write_bytes(resources.read("setup-python"))
    for path in (entrypoint, helper):
        path.chmod(0o755)
    return entrypoint, tmp_path / "log"


def _run(tmp_path: Path, **env: str) -> tuple[list[str], str]:
    entrypoint, log = _fake_root(tmp_path)
    done = subprocess.run([str(entrypoint), "env"], capture_output=True, text=True, check=True,
                          env={"PATH": os.environ["PATH"], "ROS_DISTRO": "jazzy", "ROBOCORE_TEST_LOG": str(log),
                               **env})
    return log.read_text().splitlines(), done.stdout


def test_colcons_helper_runs_in_an_isolated_python_without_site(tmp_path: Path) -> None:
    seen, _ = _run(tmp_path)
    assert seen[0] == f"helper={tmp_path}/root/robocore/setup-python"
    assert seen[1] == "flags 1 1"


def test_the_command_does_not_inherit_the_helpers_interpreter(tmp_path: Path) -> None:
    _, environment = _run(tmp_path)
    assert "COLCON_PYTHON_EXECUTABLE" not in environment
    assert "_robocore_colcon_python" not in environment


def test_an_interpreter_the_caller_chose_is_kept(tmp_path: Path) -> None:
    seen, environment = _run(tmp_path, COLCON_PYTHON_EXECUTABLE="/usr/bin/python3")
    assert seen[0] == "helper=/usr/bin/python3"
    assert "COLCON_PYTHON_EXECUTABLE=/usr/bin/python3" in environment.splitlines()


def test_the_setup_python_is_a_shell_script_that_passes_its_arguments() -> None:
    text = resources.read("setup-python").decode()
    assert text.startswith("#!/bin/sh\n")
    assert text.rstrip().endswith('exec python3 -I -S "$@"')


def test_the_entrypoint_names_the_setup_python_the_images_get_beside_it() -> None:
    # the official base copies both files into the entrypoint's folder in one COPY; the entrypoint names the path
    assert PurePosixPath(naming.SETUP_PYTHON).parent == PurePosixPath(naming.ENTRYPOINT).parent
    assert f"-x {naming.SETUP_PYTHON} ]" in resources.read("entrypoint.sh").decode()
