"""The hostile-project classes as properties, so that a field added to robot.yaml later meets the same tests: alias
structures measured by what they expand to, path spellings judged after normalisation, and link layouts
under ``.robocore/`` that robocore never writes or removes through.
"""

from __future__ import annotations

import os
import posixpath
import tempfile
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from robocore.commands.support.composefiles import write_compose_files
from robocore.config import yamltext
from robocore.config.loader import parse_robot_text
from robocore.config.risks import risky_settings
from robocore.errors import ConfigError, UnsafePath
from robocore.files import STATE_DIR
from robocore.project import STATE_FOLDERS, Project

PROPERTY = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
HEAD = "ros_distro: jazzy\nhosts:\n  - {name: main, ip: 192.168.1.10}\n"


def component(**fields: object) -> str:
    body = {"name": "c", "image": "busybox", "runs_on": "main", **fields}
    return HEAD + "components:\n  - " + yaml.safe_dump(body, default_flow_style=True, width=10_000)


def warnings_of(text: str) -> list[str]:
    return [message for _, message in risky_settings(parse_robot_text(text))]


# ------------------------------------------------------------------------------ aliases


@st.composite
def alias_documents(draw: st.DrawFn) -> tuple[str, int]:
    """A document of nested aliases around one scalar, and the bytes of text it expands to."""
    scalar = draw(st.integers(1, 200_000))
    widths = draw(st.lists(st.integers(1, 12), min_size=1, max_size=6))
    lines = [f"a0: &a0 {'x' * scalar}"]
    for level, width in enumerate(widths, start=1):
        lines.append(f"a{level}: &a{level} [{', '.join([f'*a{level - 1}'] * width)}]")
    total = scalar + sum(scalar * _product(widths[:i]) for i in range(1, len(widths) + 1))
    keys = sum(len(f"a{i}") for i in range(len(widths) + 1))
    return "\n".join(lines) + "\n", total + keys


def _product(values: list[int]) -> int:
    out = 1
    for value in values:
        out *= value
    return out


@PROPERTY
@given(alias_documents())
def test_alias_structures_are_refused_exactly_when_their_expansion_is_too_big(document: tuple[str, int]) -> None:
    text, expanded = document
    try:
        yamltext.read_yaml(text, "robot.yaml")
    except ConfigError as error:
        (line,) = error.lines()
        assert "expands to more than" in line
        assert expanded > yamltext.MAX_EXPANDED_BYTES or "values" in line
    else:
        assert expanded <= yamltext.MAX_EXPANDED_BYTES


# ------------------------------------------------------------------------------ path spellings

ABSOLUTE = ["/", "/var/run/docker.sock", "/run", "/etc", "/proc", "/sys", "/boot", "/srv/data", "/dev"]


@st.composite
def spellings(draw: st.DrawFn, path: str) -> str:
    """Another spelling of the absolute ``path``: ``./`` parts, ``x/..`` detours, repeated slashes."""
    parts = [p for p in path.split("/") if p]
    out: list[str] = []
    for part in [*parts, None]:
        for _ in range(draw(st.integers(0, 2))):
            out.append(draw(st.sampled_from([".", "", "tmp/..", "a/b/../.."])))
        if part is not None:
            out.append(part)
    return "/" + "/".join(out)


@PROPERTY
@given(st.sampled_from(ABSOLUTE).flatmap(lambda p: st.tuples(st.just(p), spellings(p))))
def test_a_volume_is_judged_by_its_normalised_path(pair: tuple[str, str]) -> None:
    path, spelled = pair
    normal = warnings_of(component(volumes=[f"{path}:/mnt/x"]))
    if spelled == path:
        assert warnings_of(component(volumes=[f"{spelled}:/mnt/x"])) == normal
        return
    # another spelling is refused outright (never fewer warnings than the path it means)
    with pytest.raises(ConfigError, match="normalised"):
        parse_robot_text(component(volumes=[f"{spelled}:/mnt/x"]))


@PROPERTY
@given(st.lists(st.sampled_from(["..", ".", "x", "", "y/.."]), min_size=1, max_size=6))
def test_a_relative_volume_that_leaves_the_project_is_refused(parts: list[str]) -> None:
    source = "./" + "/".join(parts)
    normal = posixpath.normpath(source)
    text = component(volumes=[f"{source}:/mnt/x:ro"])
    if normal.split("/")[0] == "..":
        with pytest.raises(ConfigError, match="leaves the project folder"):
            parse_robot_text(text)
    else:
        try:
            parse_robot_text(text)
        except ConfigError as error:  # the project itself ('.') is refused for another reason
            assert "leaves the project folder" not in str(error.lines())


@pytest.mark.parametrize("fields, says", [
    ({"volumes": ["/etc:/host-etc"]}, "mounts /etc of main writable"),
    ({"volumes": ["/proc:/host-proc:ro"]}, "mounts all of /proc"),
    ({"volumes": ["/boot/firmware:/fw"]}, "mounts /boot of main writable"),
    ({"devices": ["/dev/mem"]}, "memory, ports or flash"),
    ({"devices": ["/dev/mtd0"]}, "memory, ports or flash"),
    ({"devices": ["/dev/mmcblk0"]}, "passes a disk"),
])
def test_host_owning_mounts_and_devices_warn(fields: dict[str, object], says: str) -> None:
    assert any(says in warning for warning in warnings_of(component(**fields))), warnings_of(component(**fields))


def test_a_file_of_etc_mounted_read_only_does_not_warn() -> None:
    assert warnings_of(component(volumes=["/etc/localtime:/etc/localtime:ro"])) == []


def test_insecure_and_a_system_mount_root_warn_at_validate() -> None:
    text = ("ros_distro: jazzy\nhosts:\n  - {name: main, ip: 192.168.1.10, docker: tcp, insecure: true, "
            "mount_root: /etc/robocore}\n")
    found = warnings_of(text)
    assert any("plain TCP without authentication" in w for w in found)
    assert any("mount_root '/etc/robocore' is a system folder" in w for w in found)


# ------------------------------------------------------------------------------ link layouts

ROBOT = HEAD.replace("192.168.1.10", "127.0.0.1") + "components:\n  - {name: c, image: busybox, runs_on: main}\n"
PLACES = [STATE_DIR, *(f"{STATE_DIR}/{name}" for name in STATE_FOLDERS), f"{STATE_DIR}/compose/main.yaml",
          f"{STATE_DIR}/dds/super_client.xml"]


@PROPERTY
@given(st.sets(st.sampled_from(PLACES), min_size=1, max_size=3))
def test_no_link_layout_lets_a_write_or_a_clean_reach_outside(links: set[str]) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        outside = Path(tmp) / "outside"
        outside.mkdir()
        for name in ("canary", "main.yaml", "super_client.xml", ".robocore-written"):
            (outside / name).write_text("canary\nmain.yaml\n")
        root = Path(tmp) / "project"
        root.mkdir()
        (root / "robot.yaml").write_text(ROBOT)
        made = []
        for place in sorted(links, key=len):
            path = root / place
            if any(Path(m) in path.parents for m in made):
                continue  # below a link already: it would be made outside
            path.parent.mkdir(parents=True, exist_ok=True)
            os.symlink(outside, path)
            made.append(str(path))
        before = {p.name: p.read_bytes() for p in outside.iterdir()}
        project = Project.load(root)
        try:
            project.check_state_links()
            write_compose_files(project)
        except UnsafePath as error:
            (line, *_) = error.lines()
            assert "a symlink" in line
        else:
            pytest.fail(f"no refusal with links at {sorted(links)}")
        assert {p.name: p.read_bytes() for p in outside.iterdir()} == before


# ------------------------------------------------------------------------------ no traceback, no hang


@pytest.mark.parametrize("port, says", [
    ("022", "'022' is read by YAML 1.1 as the number 18"),
    ("0x16", "as the number 22"),
    ("1:30", "as the number 90"),
    ("2_2", "as the number 22"),
    ("true", "expected a whole number, got True"),
    ("9" * 5000, "could not be read as int"),
])
def test_yaml_numbers_that_surprise_are_one_line(port: str, says: str) -> None:
    with pytest.raises(ConfigError) as caught:
        parse_robot_text(f"ros_distro: jazzy\nhosts:\n  - {{name: main, ip: 192.168.1.10, ssh_port: {port}}}\n")
    (line,) = caught.value.lines()
    assert line.startswith("robot.yaml:3: ") and says in line and len(line) < 400


@pytest.mark.parametrize("key", ["entrypoint", "launch_args"])
@pytest.mark.parametrize("value", ["echo 'a", 'x:="a', "a \\"])
def test_a_shell_field_with_an_unbalanced_quote_is_refused_by_validate(key: str, value: str) -> None:
    with pytest.raises(ConfigError) as caught:
        parse_robot_text(component(**{key: value}))
    (line,) = caught.value.lines()
    assert f"components[0].{key}: is split into words as a shell would" in line


def test_a_shell_field_with_balanced_quotes_is_read() -> None:
    robot = parse_robot_text(component(entrypoint="ros2 launch pkg 'a b.py'", launch_args='x:="1 2"'))
    assert robot.components[0].entrypoint == "ros2 launch pkg 'a b.py'"


def _cli(*args: str, cwd: Path) -> tuple[int, str]:
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-m", "robocore", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=60, stdin=subprocess.DEVNULL)
    return done.returncode, done.stderr


def test_absurd_counts_and_config_files_that_are_not_files_are_one_line(tmp_path: Path) -> None:
    (tmp_path / "robot.yaml").write_text(ROBOT)
    os.mkfifo(tmp_path / "fifo")
    for args, says in [(["logs", "--tail", "9" * 5000], "--tail takes a whole number from 0 to"),
                       (["logs", "--tail", "-1"], "--tail takes a whole number"),
                       (["-f", str(tmp_path / "fifo"), "status"], "is not a regular file"),
                       (["-f", str(tmp_path), "status"], "is not a regular file"),
                       (["-f", "/dev/null", "status"], "is not a regular file"),
                       (["-p", str(tmp_path / "fifo"), "status"], "is a file, not a project folder")]:
        code, err = _cli(*args, cwd=tmp_path)
        assert code == 2 and "Traceback" not in err, (args, err)
        assert says in err and err.count("\n") <= 2, (args, err)
