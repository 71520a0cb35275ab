"""Limits on what a robot.yaml can make robocore do: size, nesting, number and length of messages,
and the warnings for dangerous but allowed settings. (Speed is measured in bench/validate_scale.py.)"""

from __future__ import annotations

import pytest
import yaml
from config_examples import SEED_EXAMPLES, Example
from conftest import MakeProject

from robocore.config import yamltext
from robocore.config.hints import MAX_SUGGESTIONS, Unknown, known_list
from robocore.config.loader import MAX_PROBLEMS, load_robot, parse_robot_text, robot_warnings
from robocore.errors import ConfigError, Problem

HEAD = "ros_distro: jazzy\nhosts:\n  - {name: main, ip: 192.168.1.10}\n"


def refusal(text: str) -> list[str]:
    with pytest.raises(ConfigError) as caught:
        parse_robot_text(text)
    return caught.value.lines()


def test_a_file_over_one_megabyte_is_refused_before_it_is_read_as_yaml(make_project: MakeProject) -> None:
    text = HEAD + "#" + "x" * yamltext.MAX_FILE_BYTES + "\n"
    project = make_project(text)
    with pytest.raises(ConfigError) as caught:
        load_robot(project)
    (line,) = caught.value.lines()
    assert line.endswith(f"robot.yaml: file is larger than 1 MB ({len(text):,} bytes); a robot.yaml is a few kilobytes")
    assert refusal("[" * (yamltext.MAX_FILE_BYTES + 1)) == [
        f"robot.yaml: file is larger than 1 MB ({yamltext.MAX_FILE_BYTES + 1:,} bytes); a robot.yaml is a few kilobytes"
    ]


def test_a_file_just_under_the_limit_is_read() -> None:
    text = HEAD + "#" + "x" * (yamltext.MAX_FILE_BYTES - len(HEAD) - 10) + "\n"
    assert parse_robot_text(text).hosts[0].name == "main"


@pytest.mark.parametrize("text", [
    "hosts: " + "[" * 100_000,
    "hosts: " + "{a: " * 10_000,
    "".join("  " * i + f"k{i}:\n" for i in range(yamltext.MAX_DEPTH + 5)) + "  " * (yamltext.MAX_DEPTH + 5) + "x\n",
])
def test_deep_nesting_is_one_line_with_its_line(text: str) -> None:
    (line,) = refusal(text)
    assert line.startswith("robot.yaml:") and f"nested more than {yamltext.MAX_DEPTH} levels deep" in line


def test_a_number_too_long_to_convert_is_one_line_about_the_number() -> None:
    (line,) = refusal("ros_distro: jazzy\nros_domain_id: " + "9" * 5000 + "\n")
    assert line.startswith("robot.yaml:2: ") and "a number of 5000 digits is too large" in line
    assert "set_int_max_str_digits" not in line and len(line) < 300


def test_nesting_within_the_limit_is_read_as_usual() -> None:
    lines = refusal("ros_distro: jazzy\nhosts: [{name: main, ip: 10.0.0.1}]\nextra: " + "[" * 40 + "]" * 40 + "\n")
    assert lines == ["robot.yaml:3: extra: unknown key 'extra' (allowed: base, common_packages, components, "
                     "discovery, hosts, image_prefix, registry, ros_distro, ros_domain_id)"]


def test_an_alias_bomb_is_one_line() -> None:
    text = "a0: &a0 [x, x, x, x, x, x, x, x, x]\n" + "".join(
        f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]\n" for i in range(1, 10))
    assert refusal(text) == [f"robot.yaml: document expands to more than {yamltext.MAX_VALUES} values (aliases?)"]


@pytest.mark.parametrize("text", [
    # a few values, each a large scalar repeated by aliases: small on disk, megabytes once expanded
    "big: &big " + "x" * 300_000 + "\nhosts: [*big, *big, *big, *big, *big, *big, *big]\n",
    # the same through nested lists and merge keys
    "s: &s " + "y" * 100_000 + "\nl1: &l1 [*s, *s, *s, *s, *s]\nl2: &l2 [*l1, *l1, *l1, *l1, *l1]\n",
    "m: &m {a: &v " + "z" * 200_000 + "}\nhosts:\n" + "".join(f"  - {{<<: *m, b{i}: *v}}\n" for i in range(20)),
])
def test_an_alias_expanding_to_too_many_bytes_is_one_line(text: str) -> None:
    assert len(text) < yamltext.MAX_FILE_BYTES
    assert refusal(text) == [f"robot.yaml: document expands to more than {yamltext.MAX_EXPANDED_BYTES:,} bytes of "
                             "text with its aliases expanded (an alias repeated too often?)"]


def test_aliases_within_the_byte_limit_are_expanded_as_usual() -> None:
    text = HEAD + "components:\n  - &c {image: busybox, runs_on: main, name: c0}\n" + "".join(
        f"  - {{<<: *c, name: c{i}}}\n" for i in range(1, 50))
    assert [c.name for c in parse_robot_text(text).components] == [f"c{i}" for i in range(50)]


def test_problems_are_capped_and_counted() -> None:
    components = "".join(f"  - {{name: c{i}, runs_on: nowhere{i}, image: busybox}}\n" for i in range(250))
    lines = refusal(HEAD + "components:\n" + components)
    assert len(lines) == MAX_PROBLEMS + 1
    assert lines[0].startswith("robot.yaml:5: components[0].runs_on: unknown host 'nowhere0' (known: main)")
    assert lines[-1] == "robot.yaml: ... and 50 more problems"


def test_known_names_and_suggestions_stay_short_for_thousands_of_hosts() -> None:
    names = [f"host{i}" for i in range(6000)]
    assert known_list(names) == ("host0, host1, host2, host3, host4, host5, host6, host7, host8, host9, ... "
                                 "(6000 in all)")
    hosts = Unknown("host", names)
    messages = [hosts.message(f"host{i}x") for i in range(MAX_SUGGESTIONS + 5)]
    assert all("did you mean" in m for m in messages[:MAX_SUGGESTIONS])
    assert not any("did you mean" in m for m in messages[MAX_SUGGESTIONS:])
    assert all(len(m) < 200 for m in messages)


def test_messages_are_printable_and_capped() -> None:
    lines = refusal(HEAD + "registry: \"\\e[2J\\u202e\"\n" + f"image_prefix: {'x' * 5000};\n")
    assert lines == [
        "robot.yaml:4: registry: must be a registry such as ghcr.io/org or localhost:5000 without control characters "
        "(got '\\x1b[2J\\u202e')",
        "robot.yaml:5: image_prefix: 'xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx... (5,001 characters) "
        "is not a valid value here (expected lower-case letters and digits, separated by '.', '_', '-' or '/', "
        "at most 128)",
    ]
    capped = yamltext.problem("robot.yaml", 1, "k", "word " * 1000 + "\x1b\n\u2028")
    assert len(capped.message) == yamltext.MAX_MESSAGE and capped.message.endswith("...")
    assert yamltext.problem("robot.yaml", 1, "k", "a\x1bb\nc").message == "a\\x1bb c"


def test_a_syntax_error_late_in_a_large_file_is_still_one_line_with_its_line() -> None:
    body = "".join(f"  - {{name: c{i}, runs_on: main, image: busybox}}\n" for i in range(3000))
    text = HEAD + "components:\n" + body + "  - {name: broken, runs_on: [main\n"
    assert len(text) > yamltext.REREAD_LIMIT
    (line,) = refusal(text)
    assert line.startswith("robot.yaml:3006: YAML syntax error:"), line


@pytest.mark.parametrize("example", SEED_EXAMPLES, ids=[e.name for e in SEED_EXAMPLES])
def test_the_yaml_reader_gives_pyyamls_values_and_the_lines_of_keys(example: Example) -> None:
    data, lines = yamltext.read_yaml(example.text, "robot.yaml")
    assert data == yaml.safe_load(example.text)
    numbered = example.text.splitlines()
    assert lines.line_of(("hosts",)) == numbered.index("hosts:") + 1
    assert lines.line_of(("hosts", 0, "ip")) == next(i for i, line in enumerate(numbered, 1) if "ip:" in line)
    assert lines.line_of(("ros_distro",)) == 1


def test_a_problem_is_an_error_unless_it_says_warning() -> None:
    assert str(Problem("robot.yaml", 3, "hosts[0].ip", "bad")) == "robot.yaml:3: hosts[0].ip: bad"
    warning = Problem("robot.yaml", 9, "components[0].privileged", "runs privileged", severity="warning")
    assert str(warning) == "robot.yaml:9: components[0].privileged: warning: runs privileged"


def test_warnings_name_their_line_and_key(make_project: MakeProject, monkeypatch: pytest.MonkeyPatch) -> None:
    text = HEAD + (
        "components:\n"
        "  - name: tools\n"
        "    runs_on: main\n"
        "    image: busybox\n"
        "    privileged: true\n"
        "    volumes: ['/:/host', '/var/run/docker.sock:/var/run/docker.sock', './data:/data']\n"
        "    devices: ['/dev/ttyUSB0', '/dev/nvme0n1p1']\n"
    )
    project = make_project(text)
    monkeypatch.chdir(project)
    robot = load_robot(project)
    got = [str(w) for w in robot_warnings(project / "robot.yaml", robot, project)]
    assert [w.split(": warning: ")[0] for w in got] == [
        "robot.yaml:8: components[0].privileged",
        "robot.yaml:9: components[0].volumes[0]",
        "robot.yaml:9: components[0].volumes[1]",
        "robot.yaml:10: components[0].devices[1]",
    ], got
    assert "mounts the Docker socket of main" in got[2]
    assert robot_warnings(project / "robot.yaml", parse_robot_text(HEAD)) == []


@pytest.mark.parametrize(("distro", "domain", "warned"), [
    ("jazzy", 101, False), ("jazzy", 102, True), ("jazzy", 232, True), ("noetic", 200, False)])
def test_a_ros2_domain_whose_ports_fall_in_the_ephemeral_range_is_a_warning_on_its_line(
        distro: str, domain: int, warned: bool, make_project: MakeProject, monkeypatch: pytest.MonkeyPatch) -> None:
    project = make_project(f"ros_distro: {distro}\nros_domain_id: {domain}\n"
                           "hosts:\n  - {name: main, ip: 192.168.1.10}\n")
    monkeypatch.chdir(project)
    got = [str(w) for w in robot_warnings(project / "robot.yaml", load_robot(project), project)]
    if not warned:
        assert got == []
        return
    assert len(got) == 1 and got[0].startswith("robot.yaml:2: ros_domain_id: warning: "), got
    assert f"from {7400 + 250 * domain}" in got[0] and "0-101" in got[0]
