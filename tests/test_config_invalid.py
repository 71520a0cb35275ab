"""Invalid robot.yaml files: each problem on its own line, with the right line number and key path."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import pytest
from conftest import MakeProject

from robocore.config.loader import load_robot, parse_robot_text
from robocore.errors import ConfigError

BASE = """\
ros_distro: humble
ros_domain_id: 7
image_prefix: demo-
hosts:
  - name: rpi5
    ip: 192.168.1.20
    user: robot
    arch: arm64
  - name: dev
    ip: 127.0.0.1
    user: me
components:
  - name: talker
    folder: components/talker
    runs_on: rpi5
  - name: listener
    folder: components/listener
    runs_on: dev
"""
FOLDERS = ("components/talker", "components/listener")


def edit(
    replace: dict[int, str] | None = None,
    *,
    after: dict[int, str] | None = None,
    delete: tuple[int, ...] = (),
    base: str = BASE,
) -> str:
    """BASE with line N replaced (``replace``), text inserted after line N (``after``) or lines deleted.

    Line numbers always refer to BASE; inserted text may span several lines.
    """
    out: list[str] = []
    for number, line in enumerate(base.splitlines(), start=1):
        if number in delete:
            continue
        out.append((replace or {}).get(number, line))
        if after and number in after:
            out.append(after[number].rstrip("\n"))
    if after and 0 in after:
        out.insert(0, after[0].rstrip("\n"))
    return "\n".join(out) + "\n"


@dataclass(frozen=True)
class Case:
    """An invalid document, the line and text of the problem it must give, and how many problems in all."""

    id: str
    text: str
    line: int | None
    fragment: str
    count: int = 1
    files: tuple[str, ...] = field(default=())


CASES = [
    Case(
        "unknown-distro",
        edit({1: "ros_distro: iron"}),
        1,
        "ros_distro: 'iron' is not one of: melodic, noetic, humble, jazzy, kilted, rolling",
    ),
    Case("distro-near-miss", edit({1: "ros_distro: jazy"}), 1, "did you mean 'jazzy'?"),
    Case(
        "domain-id-too-big",
        edit({2: "ros_domain_id: 233"}),
        2,
        "ros_domain_id: 233 is out of range (must be at most 232)",
    ),
    Case(
        "domain-id-negative",
        edit({2: "ros_domain_id: -1"}),
        2,
        "ros_domain_id: -1 is out of range (must be at least 0)",
    ),
    Case(
        "domain-id-not-a-number",
        edit({2: "ros_domain_id: seven"}),
        2,
        "ros_domain_id: expected a whole number, got 'seven'",
    ),
    Case(
        "image-prefix-uppercase", edit({3: "image_prefix: Demo-"}), 3, "image_prefix: 'Demo-' is not a valid value here"
    ),
    Case(
        "unknown-top-level-key",
        edit(after={3: "bogus: 1"}),
        4,
        "bogus: unknown key 'bogus' (allowed: base, common_packages, components, discovery, hosts, image_prefix, "
        "registry, ros_distro, ros_domain_id)",
    ),
    Case(
        "top-level-key-near-miss",
        edit({12: "component:"}),
        12,
        "component: unknown key 'component'; did you mean 'components'?",
    ),
    Case("unknown-host-key", edit(after={8: "    hostname: pi"}), 9, "hosts[0].hostname: unknown key 'hostname'"),
    Case(
        "unknown-runs-on",
        edit({15: "    runs_on: rpi6"}),
        15,
        "components[0].runs_on: unknown host 'rpi6' (known: rpi5, dev); did you mean 'rpi5'?",
    ),
    Case(
        "duplicate-host-name",
        edit({9: "  - name: rpi5"}),
        9,
        "hosts[1].name: duplicate name 'rpi5' (also hosts[0])",
        count=2,
    ),
    Case(
        "duplicate-component-name",
        edit({16: "  - name: talker"}),
        16,
        "components[1].name: duplicate name 'talker' (also components[0])",
    ),
    Case(
        "bad-component-name", edit({13: "  - name: 1talker"}), 13, "components[0].name: '1talker' is not a valid value"
    ),
    Case("host-ip-missing", edit(delete=(6,)), 5, "hosts[0].ip: required key is missing"),
    Case("ros-distro-missing", edit(delete=(1,)), 1, "ros_distro: required key is missing"),
    Case(
        "no-hosts",
        edit({4: "hosts: []"}, delete=(5, 6, 7, 8, 9, 10, 11, 15, 18)),
        4,
        "hosts: needs at least 1 item(s)",
        count=3,
    ),
    Case(
        "host-is-a-string",
        edit({5: "  - rpi5"}, delete=(6, 7, 8)),
        5,
        "hosts[0]: expected a mapping of keys, got 'rpi5'",
        count=2,
    ),
    Case(
        "hosts-is-a-mapping",
        edit({4: "hosts: {rpi5: 192.168.1.20}"}, delete=(5, 6, 7, 8, 9, 10, 11)),
        4,
        "hosts: expected a list, got a mapping",
    ),
    Case("bad-arch", edit({8: "    arch: armhf"}), 8, "hosts[0].arch: 'armhf' is not one of: amd64, arm64"),
    Case(
        "ip-with-space",
        edit({6: "    ip: 192.168.1.20 extra"}),
        6,
        "hosts[0].ip: must be an IP address or a host name (got '192.168.1.20 extra')",
    ),
    Case("bad-user", edit({7: "    user: Robot User"}), 7, "hosts[0].user: 'Robot User' is not a valid value here"),
    Case(
        "relative-mount-root",
        edit(after={8: "    mount_root: robocore"}),
        9,
        "hosts[0].mount_root: must be an absolute path",
    ),
    Case(
        "tcp-without-insecure",
        edit(after={8: "    docker: tcp"}),
        9,
        "hosts[0].docker: plain TCP exposes the Docker daemon without authentication",
    ),
    Case(
        "insecure-without-tcp",
        edit(after={8: "    insecure: true"}),
        9,
        "hosts[0].insecure: insecure: true only applies to docker: tcp",
    ),
    Case("tls-without-files", edit(after={8: "    docker: tls"}), 9, "hosts[0].docker: docker: tls needs tls:"),
    Case(
        "tls-files-without-tls",
        edit(after={8: "    tls: {ca_cert: ca.pem, client_cert: c.pem, client_key: k.pem}"}),
        9,
        "hosts[0].tls: tls files given but docker is 'ssh', not 'tls'",
        count=4,
    ),
    Case(
        "tls-file-missing",
        edit(
            after={
                8: "    docker: tls\n    tls:\n      ca_cert: certs/ca.pem\n      client_cert: certs/cert.pem\n"
                "      client_key: certs/key.pem"
            }
        ),
        11,
        "hosts[0].tls.ca_cert: file 'certs/ca.pem' not found",
        files=("certs/cert.pem", "certs/key.pem"),
    ),
    Case(
        "docker-port-with-ssh",
        edit(after={8: "    docker_port: 2375"}),
        9,
        "hosts[0].docker_port: docker_port only applies to docker: tcp or tls (not 'ssh')",
    ),
    Case(
        "missing-folder",
        edit({14: "    folder: components/talkr"}),
        14,
        "components[0].folder: folder 'components/talkr' does not exist",
    ),
    Case(
        "folder-outside-project",
        edit({14: "    folder: ../elsewhere"}),
        14,
        "components[0].folder: '../elsewhere' points outside the project folder",
    ),
    Case(
        "absolute-folder",
        edit({14: "    folder: /etc"}),
        14,
        "components[0].folder: '/etc' must be relative to the project folder",
    ),
    Case(
        "folder-is-a-file",
        edit({14: "    folder: notes.txt"}),
        14,
        "'notes.txt' is a file, not a folder",
        files=("notes.txt",),
    ),
    Case(
        "image-and-folder",
        edit(after={15: "    image: ros:humble"}),
        14,
        "components[0].folder: cannot be combined with image: (component 'talker' uses a pre-built image)",
    ),
    Case(
        "image-and-apt",
        edit(after={15: "    image: ros:humble\n    apt_packages: [curl]"}, delete=(14,)),
        16,
        "components[0].apt_packages: cannot be combined with image:",
    ),
    Case(
        "image-and-repositories",
        edit(after={15: "    image: ros:humble\n    repositories:\n      - url: https://x/y"}, delete=(14,)),
        16,
        "components[0].repositories: cannot be combined with image:",
    ),
    Case(
        "port-without-host-port",
        edit(after={15: "    ports: ['80']"}),
        16,
        "components[0].ports[0]: '80' is not [ip:]host_port:container_port[/tcp|udp]",
    ),
    Case(
        "port-out-of-range",
        edit(after={15: "    ports:\n      - 70000:80"}),
        17,
        "components[0].ports[0]: '70000:80': ports must be between 1 and 65535",
    ),
    Case(
        "port-ranges-differ",
        edit(after={15: "    ports: ['8000-8002:9000-9001']"}),
        16,
        "'8000-8002:9000-9001': host and container port ranges differ in length",
    ),
    Case(
        "port-as-number",
        edit(after={15: "    ports: [8080]"}),
        16,
        "components[0].ports[0]: expected a string, got 8080 (quote it to keep it as text)",
    ),
    Case(
        "ports-with-host-network",
        edit(after={15: "    network: host\n    ports: ['8080:80']"}),
        17,
        "components[0].ports: ports are ignored with network: host",
    ),
    Case(
        "device-relative",
        edit(after={15: "    devices: [ttyUSB0]"}),
        16,
        "components[0].devices[0]: 'ttyUSB0' is not host_path[:container_path[:rwm]]",
    ),
    Case(
        "device-bad-permissions",
        edit(after={15: "    devices:\n      - /dev/ttyUSB0:/dev/ttyUSB0:rx"}),
        17,
        "'/dev/ttyUSB0:/dev/ttyUSB0:rx': permissions must be letters of 'rwm'",
    ),
    Case(
        "volume-without-container-path",
        edit(after={15: "    volumes: [/data]"}),
        16,
        "components[0].volumes[0]: '/data' is not host_path:container_path[:ro|rw]",
    ),
    Case(
        "volume-bad-mode",
        edit(after={15: "    volumes: ['/data:/data:rwx']"}),
        16,
        "'/data:/data:rwx': mode must be ro or rw",
    ),
    Case(
        "remote-read-only-volume-outside-the-project",
        edit(after={15: "    volumes: ['../shared:/shared:ro', './ok:/ok:ro']"}),
        16,
        "components[0].volumes[0]: '../shared:/shared:ro': a project path that leaves the project folder means "
        "nothing on a robot; name a host folder by its absolute path ('../shared' is not in the project)",
    ),
    Case(
        "bad-env-name",
        edit(after={15: "    environment:\n      MY-VAR: 1"}),
        17,
        "components[0].environment.MY-VAR: 'MY-VAR' is not a valid environment variable name",
    ),
    Case(
        "bad-bool",
        edit(after={15: "    nvidia: maybe"}),
        16,
        "components[0].nvidia: expected true or false, got 'maybe'",
    ),
    Case(
        "apt-packages-not-a-list",
        edit(after={15: "    apt_packages: curl"}),
        16,
        "components[0].apt_packages: expected a list, got 'curl' (write it as [curl] or as '- curl' lines)",
    ),
    Case(
        "bad-apt-package",
        edit(after={15: "    apt_packages: ['Curl Tools']"}),
        16,
        "components[0].apt_packages[0]: 'Curl Tools' is not a valid value here",
    ),
    Case(
        "repository-version-number",
        edit(after={15: "    repositories:\n      - url: https://x/y\n        version: 1.0"}),
        18,
        "components[0].repositories[0].version: expected a string, got 1.0 (quote it",
    ),
    Case(
        "repository-folder-escapes",
        edit(after={15: "    repositories:\n      - url: https://x/y\n        folder: ../z"}),
        18,
        "components[0].repositories[0].folder: '../z' must be a relative folder under src/",
    ),
    Case(
        "repositories-share-folder",
        edit(
            after={
                15: "    repositories:\n      - {url: https://x/a, folder: a}\n      - {url: https://x/b, folder: a}"
            }
        ),
        18,
        "components[0].repositories[1].folder: two repositories use folder 'a' (also repositories[0])",
    ),
    Case(
        "bad-restart",
        edit(after={15: "    restart: sometimes"}),
        16,
        "components[0].restart: 'sometimes' is not one of: no, always, unless-stopped, on-failure",
    ),
    Case(
        "unknown-base-kind",
        edit(after={3: "base:\n  kind: docker"}),
        5,
        "base.kind: 'docker' is not one of: official, wheels",
    ),
    Case(
        "discovery-unknown-host",
        edit(after={3: "discovery:\n  servers:\n    - host: rpi6"}),
        6,
        "discovery.servers[0].host: unknown host 'rpi6' (known: rpi5, dev)",
    ),
    Case(
        "discovery-privileged-port",
        edit(after={3: "discovery:\n  servers:\n    - {host: rpi5, port: 80}"}),
        6,
        "discovery.servers[0].port: 80 is out of range (must be at least 1024)",
    ),
    Case(
        "discovery-bad-transport",
        edit(after={3: "discovery:\n  transport: tcp"}),
        5,
        "discovery.transport: 'tcp' is not one of: shm, udp",
    ),
    Case(
        "discovery-on-loopback-host",
        edit(after={3: "discovery:\n  servers:\n    - host: dev"}),
        6,
        "discovery.servers[0].host: discovery server on 'dev' listens on loopback address '127.0.0.1', which remote "
        "hosts (rpi5) cannot reach",
    ),
    Case(
        "default-discovery-on-loopback-host",
        edit(
            {
                5: "  - name: dev",
                6: "    ip: localhost",
                7: "    user: me",
                8: "  - name: rpi5",
                9: "    ip: 10.0.0.2",
                10: "    user: robot",
                11: "    arch: arm64",
            }
        ),
        6,
        "hosts[0].ip: the discovery server runs on the first host by default, but 'localhost' is a loopback address",
    ),
    Case(
        "common-package-without-source",
        edit(after={11: "common_packages:\n  - name: my_msgs"}),
        13,
        "common_packages[0]: needs a folder or a repo",
    ),
    Case(
        "common-package-branch-without-repo",
        edit(after={11: "common_packages:\n  - name: my_msgs\n    folder: components/talker\n    branch: main"}),
        15,
        "common_packages[0].branch: branch needs repo",
    ),
    Case("duplicate-key", edit(after={15: "    runs_on: dev"}), 16, "components[0].runs_on: this key appears twice"),
    Case("yaml-syntax-error", edit({13: "  - name: [talker"}), 14, "YAML syntax error:"),
    Case(
        "yaml-tab-indent",
        edit({14: "\tfolder: components/talker"}),
        14,
        "found character '\\t' that cannot start any token",
    ),
    Case("top-level-list", "- ros_distro: humble\n", 1, "top level must be a mapping of keys"),
    Case("comments-only", "# nothing here\n\n", None, "file is empty"),
    Case(
        "python-tag",
        edit({3: "image_prefix: !!python/object/apply:os.system [ls]"}),
        3,
        "YAML error: could not determine a constructor",
    ),
]


def _problem_lines(error: ConfigError) -> list[str]:
    return error.lines()


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_invalid_config_is_reported_with_line_and_message(tmp_path: Path, case: Case) -> None:
    for folder in FOLDERS:
        (tmp_path / folder).mkdir(parents=True)
    for name in case.files:
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("x")
    with pytest.raises(ConfigError) as caught:
        parse_robot_text(case.text, file="robot.yaml", project=tmp_path)
    lines = _problem_lines(caught.value)
    where = f"robot.yaml:{case.line}: " if case.line is not None else "robot.yaml: "
    assert any(line.startswith(where) and case.fragment in line for line in lines), "\n".join(lines)
    assert len(lines) == case.count, "\n".join(lines)
    assert all(line.startswith("robot.yaml") and "\n" not in line for line in lines)


def test_there_are_at_least_30_distinct_cases() -> None:
    assert len({c.id for c in CASES}) == len(CASES) >= 30
    assert len({c.text for c in CASES}) == len(CASES)


def test_the_base_document_is_valid(tmp_path: Path) -> None:
    for folder in FOLDERS:
        (tmp_path / folder).mkdir(parents=True)
    robot = parse_robot_text(BASE, project=tmp_path)
    assert [c.name for c in robot.components] == ["talker", "listener"]


def test_bad_type_and_unknown_host_in_the_same_component_are_both_reported(tmp_path: Path) -> None:
    for folder in FOLDERS:
        (tmp_path / folder).mkdir(parents=True)
    text = edit({15: "    runs_on: rpi6"}, after={15: "    nvidia: maybe\n    ports: ['1:2:3:4']"})
    with pytest.raises(ConfigError) as caught:
        parse_robot_text(text, project=tmp_path)
    assert caught.value.lines() == [
        "robot.yaml:15: components[0].runs_on: unknown host 'rpi6' (known: rpi5, dev); did you mean 'rpi5'?",
        "robot.yaml:16: components[0].nvidia: expected true or false, got 'maybe'",
        "robot.yaml:17: components[0].ports[0]: '1:2:3:4' is not [ip:]host_port:container_port[/tcp|udp]",
    ]


def test_every_problem_of_a_file_is_reported_at_once_sorted_by_line(tmp_path: Path) -> None:
    text = edit(
        {1: "ros_distro: iron", 8: "    arch: x86", 14: "    folder: ../out", 18: "    runs_on: nowhere"},
        after={3: "extra: 1"},
        delete=(11,),
    )
    with pytest.raises(ConfigError) as caught:
        parse_robot_text(text, project=tmp_path)
    got = [(p.line, p.path) for p in caught.value.problems]
    assert got == [
        (1, "ros_distro"),
        (4, "extra"),
        (9, "hosts[0].arch"),
        (14, "components[0].folder"),
        (17, "components[1].folder"),
        (18, "components[1].runs_on"),
    ]


def test_a_host_with_a_bad_field_still_counts_as_known(tmp_path: Path) -> None:
    """A component on a host whose other fields are wrong is not also told the host is unknown."""
    for folder in FOLDERS:
        (tmp_path / folder).mkdir(parents=True)
    with pytest.raises(ConfigError) as caught:
        parse_robot_text(edit({6: "    ip: [1, 2]"}), project=tmp_path)
    assert caught.value.lines() == ["robot.yaml:6: hosts[0].ip: expected a string, got a list"]


def test_without_a_project_folder_checks_are_skipped() -> None:
    robot = parse_robot_text(edit({14: "    folder: does/not/exist"}))
    assert robot.components[0].folder == "does/not/exist"


# --- files ------------------------------------------------------------------------------------


def test_missing_project_folder(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as caught:
        load_robot(tmp_path / "nope")
    (line,) = caught.value.lines()
    assert line.endswith("nope: project folder does not exist")


def test_missing_robot_yaml(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as caught:
        load_robot(tmp_path)
    (line,) = caught.value.lines()
    assert line.startswith(str(tmp_path / "robot.yaml")) or line.startswith("robot.yaml")
    assert "file not found" in line


@pytest.mark.parametrize(
    "content, message",
    [
        (b"", "file is empty"),
        (b"   \n\n", "file is empty"),
        (b"# only a comment\n", "file is empty"),
        (b"ros_distro: humble\n\xff\xfe\n", "not UTF-8 text (byte 19)"),
        (b"ros_distro: humble\x00\n", "not a text file (contains NUL bytes)"),
    ],
)
def test_unreadable_or_empty_robot_yaml(make_project: MakeProject, content: bytes, message: str) -> None:
    project = make_project("")
    (project / "robot.yaml").write_bytes(content)
    with pytest.raises(ConfigError) as caught:
        load_robot(project)
    (line,) = caught.value.lines()
    assert f"robot.yaml: {message}" in line, line


def test_robot_yaml_is_a_folder(make_project: MakeProject) -> None:
    project = make_project("", name="p")
    (project / "robot.yaml").unlink()
    (project / "robot.yaml").mkdir()
    with pytest.raises(ConfigError) as caught:
        load_robot(project)
    assert caught.value.lines()[0].endswith("robot.yaml: is not a file")


def test_file_name_is_relative_to_the_current_folder(
    make_project: MakeProject, monkeypatch: pytest.MonkeyPatch
) -> None:
    project = make_project(edit({1: "ros_distro: iron"}), FOLDERS)
    monkeypatch.chdir(project.parent)
    with pytest.raises(ConfigError) as caught:
        load_robot(project)
    assert caught.value.lines() == [
        f"{project.name}/robot.yaml:1: ros_distro: 'iron' is not one of: "
        "melodic, noetic, humble, jazzy, kilted, rolling"
    ]


def test_problems_found_after_loading_get_their_lines(make_project: MakeProject) -> None:
    """located(): checks outside the config package (e.g. the wheels base) still report robot.yaml lines."""
    from robocore.config.loader import located

    project = make_project(BASE, FOLDERS)
    error = located(project / "robot.yaml", [(("hosts", 0, "arch"), "arm64: no wheels"), (("ros_distro",), "no")])
    assert [(p.line, p.path, p.message) for p in error.problems] == [
        (1, "ros_distro", "no"),
        (8, "hosts[0].arch", "arm64: no wheels"),
    ]
    (project / "robot.yaml").unlink()
    assert [p.line for p in located(project / "robot.yaml", [(("ros_distro",), "no")]).problems] == [None]


def test_validate_reports_what_the_wheels_base_cannot_build(make_project: MakeProject) -> None:
    from robocore.commands import validate
    from robocore.commands.support.context import Options

    project = make_project(edit({1: "ros_distro: humble\nbase: {kind: wheels}"}), FOLDERS)
    with pytest.raises(ConfigError) as caught:
        validate.run(Options(project_dir=project))
    assert [(p.line, p.path) for p in caught.value.problems] == [(1, "ros_distro"), (9, "hosts[0].arch")]
    assert "humble has no ROS 2 wheels on PyPI" in caught.value.problems[0].message


def test_validate_prepare_base_and_stage_refuse_the_same_robot_shape_in_the_same_lines(
        make_project: MakeProject) -> None:
    """A wheels robot whose Fast DDS server (on the first host, arm64) would need an arm64 wheels base: validate
    says so, in the one line prepare-base and stage say it (one check, made where each of them starts)."""
    from robocore.commands import prepare_base, stage, validate
    from robocore.commands.support.context import Options

    project = make_project(edit({1: "ros_distro: jazzy\nbase: {kind: wheels}", 15: "    runs_on: dev"}), FOLDERS)
    seen = []
    steps = [(validate.run, False), (lambda o: prepare_base.prepare_base(o, force=False), True),
             (lambda o: stage.stage(o, refresh=False, component=None, force=False), True)]
    for step, dry_run in steps:  # the image steps' dry runs: they refuse before contacting any daemon
        with pytest.raises(ConfigError) as caught:
            step(Options(project_dir=project, dry_run=dry_run))
        seen.append(caught.value.lines())
    [line] = seen[0]
    assert line.endswith("robot.yaml:9: hosts[0].arch: arm64: this host runs a Fast DDS discovery server on the base "
                         "of its arch, and ROS 2 wheels exist for amd64 only; use base.kind: official for this robot")
    assert seen == [seen[0]] * 3, seen


def test_folder_symlinked_outside_the_project_is_refused(tmp_path: Path) -> None:
    outside = tmp_path / "outside"
    outside.mkdir()
    project = tmp_path / "robot"
    (project / "components").mkdir(parents=True)
    (project / "components" / "listener").mkdir()
    (project / "components" / "talker").symlink_to(outside)
    with pytest.raises(ConfigError) as caught:
        parse_robot_text(BASE, project=project)
    assert caught.value.lines() == [
        "robot.yaml:14: components[0].folder: 'components/talker' points outside the project folder"
    ]
