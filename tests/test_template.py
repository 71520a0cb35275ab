"""The copier template and ``robocore init``: what gets generated, and that it is a working project."""

from __future__ import annotations

import ast
import io
import json
import shutil
import subprocess
import sys
import types
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterator
from contextlib import redirect_stdout
from pathlib import Path
from typing import Any

import jsonschema
import pytest
import yaml
from template_repo import TEMPLATE, hide_origin

from robocore.adapters import copier_adapter
from robocore.commands import init
from robocore.config.loader import load_robot
from robocore.config.schema import robot_schema, schema_json
from robocore.errors import UsageError
from robocore.project import ProjectFolder

PROJECT_TASKS = ["validate", "prepare-base", "stage", "build", "sync", "run", "shell", "connect",
                 "release", "status", "logs", "down"]
PACKAGES = {"talker": "demo_talker", "listener": "demo_listener"}


@pytest.fixture(autouse=True)
def _bundled_template(monkeypatch: pytest.MonkeyPatch) -> None:
    hide_origin(monkeypatch)


def make(path: Path, *, distro: str | None = None, base: str | None = None, dry_run: bool = False) -> Path:
    init.run(path, defaults=True, distro=distro, base=base, dry_run=dry_run)
    return path


@pytest.fixture(scope="module")
def project(tmp_path_factory: pytest.TempPathFactory) -> Path:
    with pytest.MonkeyPatch.context() as monkeypatch:
        hide_origin(monkeypatch)
        return make(tmp_path_factory.mktemp("gen") / "myrobot")


def robot_doc(project: Path) -> dict[str, Any]:
    doc = yaml.safe_load((project / "robot.yaml").read_text())
    assert isinstance(doc, dict)
    return doc


# ---------------------------------------------------------------- robocore init --defaults


def test_init_writes_the_project_files(project: Path) -> None:
    for rel in ["robot.yaml", "tasks.py", "README.md", ".gitignore", ".copier-answers.yml",
                ".robocore/robot.schema.json", ".robocore/fleet.schema.json", "fleet.example.yaml",
                "noxfile.py", "pytest.ini", "tests/graph/test_talker_listener.py",
                ".github/workflows/robot.yml",
                "components/talker/src/demo_talker/package.xml",
                "components/listener/src/demo_listener/package.xml"]:
        assert (project / rel).is_file(), rel
    assert not list(project.rglob("*.jinja"))
    assert not (project / "copier.yml").exists()
    assert not (project / ".gitlab-ci.yml").exists()


def test_generated_robot_yaml_validates_with_the_defaults(project: Path) -> None:
    robot = load_robot(project)
    assert robot.ros_distro.value == "jazzy"
    assert robot.base.kind.value == "official"
    assert [h.name for h in robot.hosts] == ["devmachine"]
    host = robot.hosts[0]
    assert host.ip == "127.0.0.1" and host.is_local
    assert host.user == init.current_user()
    assert host.arch.value == init.default_arch()
    assert [(c.name, c.folder, c.runs_on, c.entrypoint) for c in robot.components] == [
        ("talker", "components/talker", "devmachine", "ros2 run demo_talker talker"),
        ("listener", "components/listener", "devmachine", "ros2 run demo_listener listener"),
    ]
    assert robot.image_prefix == "myrobot-"


def test_robot_yaml_points_editors_at_the_schema_init_wrote(project: Path) -> None:
    first = (project / "robot.yaml").read_text().splitlines()[0]
    assert first == "# yaml-language-server: $schema=.robocore/robot.schema.json"
    written = ProjectFolder(project).schema_file.read_text()
    assert json.loads(written) == json.loads(schema_json())
    jsonschema.validate(robot_doc(project), robot_schema())


def test_gitignore_covers_generated_files(project: Path) -> None:
    lines = (project / ".gitignore").read_text().splitlines()
    assert ".robocore/" in lines
    assert {"build/", "install/", "log/", ".nox/", ".pytest_cache/", ".venv-ci/"} <= set(lines)


def test_answers_file_records_the_answers(project: Path) -> None:
    answers = yaml.safe_load((project / ".copier-answers.yml").read_text())
    assert answers["_src_path"] == str(TEMPLATE)
    assert answers["project_name"] == "myrobot"
    assert answers["ros_distro"] == "jazzy"
    assert answers["base_kind"] == "official"
    assert answers["hosts"] == init.default_hosts()
    assert answers["ci"] == "github"
    assert answers["robocore_repository"] == ""  # the bundled template: robocore's repository is unknown
    assert "_commit" not in answers
    assert not {"robocore_ref", "robocore_requirement", "with_github_ci", "with_gitlab_ci"} & set(answers)


def test_invoke_list_in_the_project_shows_the_tasks(project: Path) -> None:
    out = subprocess.run([sys.executable, "-m", "invoke", "--list"], cwd=project, capture_output=True,
                         text=True, check=True, timeout=60).stdout
    listed = {line.split()[0] for line in out.splitlines() if line.startswith("  ") and line.strip()}
    assert set(PROJECT_TASKS) <= listed, out


def test_invoke_validate_in_the_project_succeeds(project: Path) -> None:
    done = subprocess.run([sys.executable, "-m", "invoke", "validate"], cwd=project, capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert "ok" in done.stderr + done.stdout


def test_project_readme_documents_the_workflow(project: Path) -> None:
    readme = (project / "README.md").read_text()
    assert readme.startswith("# myrobot\n")
    for step in ["invoke stage", "invoke build", "invoke sync", "invoke run", "invoke shell --component",
                 "invoke connect --component", "robocore schema > .robocore/robot.schema.json"]:
        assert step in readme, step
    assert "{{" not in readme


# ---------------------------------------------------------------- answers change the result


def test_base_wheels_and_distro_kilted(tmp_path: Path) -> None:
    project = make(tmp_path / "k", distro="kilted", base="wheels")
    robot = load_robot(project)
    assert robot.ros_distro.value == "kilted"
    assert robot.base.kind.value == "wheels"
    text = (project / "robot.yaml").read_text()
    assert "ros-kilted-rviz2" in text
    answers = yaml.safe_load((project / ".copier-answers.yml").read_text())
    assert (answers["ros_distro"], answers["base_kind"]) == ("kilted", "wheels")


@pytest.mark.parametrize("distro", ["humble", "rolling"])
def test_every_distro_renders_a_valid_project(tmp_path: Path, distro: str) -> None:
    assert load_robot(make(tmp_path / distro, distro=distro)).ros_distro.value == distro


def test_several_hosts_with_extra_keys(tmp_path: Path) -> None:
    hosts = [
        {"name": "rpi5", "ip": "pi5.local", "user": "robot", "arch": "arm64", "ssh_port": 2222, "docker": "ssh"},
        {"name": "devmachine", "ip": "127.0.0.1", "user": "me", "arch": "amd64"},
    ]
    copier_adapter.copy(copier_adapter.CopyRequest(template=str(TEMPLATE), destination=tmp_path / "r",
                                                   data={"hosts": hosts}, defaults=True))
    robot = load_robot(tmp_path / "r")
    assert [(h.name, h.ip, h.user, h.arch.value) for h in robot.hosts] == [
        ("rpi5", "pi5.local", "robot", "arm64"), ("devmachine", "127.0.0.1", "me", "amd64")]
    assert robot.hosts[0].ssh_port == 2222 and robot.hosts[0].access.value == "ssh"
    assert {c.runs_on for c in robot.components} == {"rpi5"}


def test_values_that_yaml_would_misread_are_quoted(tmp_path: Path) -> None:
    hosts = [{"name": "on", "ip": "10.0.0.5", "user": "no", "arch": "amd64"}]
    copier_adapter.copy(copier_adapter.CopyRequest(template=str(TEMPLATE), destination=tmp_path / "q",
                                                   data={"hosts": hosts}, defaults=True))
    robot = load_robot(tmp_path / "q")
    assert (robot.hosts[0].name, robot.hosts[0].user) == ("on", "no")
    assert robot.components[0].runs_on == "on"


@pytest.mark.parametrize(("hosts", "message"), [
    ([], "non-empty YAML list"),
    ("devmachine", "non-empty YAML list"),
    ([{"name": "x"}], "needs at least a name and an ip"),
    ([{"name": "x", "ip": "10.0.0.1", "arch": "riscv64"}], "arch must be amd64 or arm64"),
])
def test_bad_host_answers_are_one_line_errors(tmp_path: Path, hosts: Any, message: str) -> None:
    with pytest.raises(copier_adapter.TemplateError) as caught:
        copier_adapter.copy(copier_adapter.CopyRequest(template=str(TEMPLATE), destination=tmp_path / "bad",
                                                       data={"hosts": hosts}, defaults=True))
    lines = caught.value.lines()
    assert len(lines) == 1 and message in lines[0] and "hosts" in lines[0]
    assert not (tmp_path / "bad").exists()


def test_project_name_defaults_to_the_folder_and_sets_the_image_prefix(tmp_path: Path) -> None:
    copier_adapter.copy(copier_adapter.CopyRequest(template=str(TEMPLATE), destination=tmp_path / "Big_Bot",
                                                   defaults=True))
    robot = load_robot(tmp_path / "Big_Bot")
    assert robot.image_prefix == "big_bot-"
    copier_adapter.copy(copier_adapter.CopyRequest(template=str(TEMPLATE), destination=tmp_path / "other",
                                                   data={"project_name": "rover"}, defaults=True))
    assert load_robot(tmp_path / "other").image_prefix == "rover-"
    assert (tmp_path / "other" / "README.md").read_text().startswith("# rover\n")


def test_init_turns_an_awkward_folder_name_into_a_project_name(tmp_path: Path) -> None:
    project = make(tmp_path / "my robot!")
    assert yaml.safe_load((project / ".copier-answers.yml").read_text())["project_name"] == "my-robot"
    assert load_robot(project).image_prefix == "my-robot-"


def uncommented_example(text: str, first: str) -> str:
    """The commented-out example block of a generated robot.yaml that starts at ``  # - name: FIRST``, uncommented
    (components' indent); it ends at the first line that is not ``  # ...``."""
    lines = text.splitlines()
    block = []
    for line in lines[lines.index(f"  # - name: {first}"):]:
        if not line.startswith("  # "):
            break
        block.append("  " + line[4:])
    return "\n".join(block) + "\n"


def test_desktop_example_is_commented_out_and_valid_once_uncommented(project: Path) -> None:
    text = (project / "robot.yaml").read_text()
    assert {"desktop", "clock"}.isdisjoint(c.name for c in load_robot(project).components)
    comments = text[:text.index("  # - name: desktop")]
    assert "http://<host ip>:6080/vnc.html" in comments and "invoke shell --component" in comments
    assert "gui: true" in comments and "ghcr.io" not in text  # built from Debian packages: no registry
    (project / "robot.yaml").write_text(text + "\n" + uncommented_example(text, "desktop"))
    try:
        robot = load_robot(project)
    finally:
        (project / "robot.yaml").write_text(text)
    desktop, clock = robot.component("desktop"), robot.component("clock")
    assert desktop.desktop is not None and desktop.desktop.web_port == 6080 and desktop.runs_on == "devmachine"
    assert {"tigervnc-standalone-server", "tigervnc-tools"} <= set(desktop.apt_packages) and desktop.folder is None
    assert clock.gui == "desktop" and clock.runs_on == "devmachine" and clock.entrypoint == "xclock -update 1"


def test_fleet_example_is_a_commented_fleet_file_that_validates_once_copied(project: Path, tmp_path: Path) -> None:
    from robocore.config.fleet import load_fleet
    from robocore.config.schema import fleet_schema
    from robocore.plan.fleet import plan_waves

    example = (project / "fleet.example.yaml").read_text()
    assert not (project / "fleet.yaml").exists()  # only an example: the project stays one robot
    assert example.splitlines()[0] == "# yaml-language-server: $schema=.robocore/fleet.schema.json"
    assert sum(line.lstrip().startswith("#") for line in example.splitlines()) >= 15
    assert json.loads(ProjectFolder(project).fleet_schema_file.read_text()) == fleet_schema()
    jsonschema.validate(yaml.safe_load(example), fleet_schema())
    copy = tmp_path / "copy"
    copy.mkdir()
    (copy / "robot.yaml").write_text((project / "robot.yaml").read_text())
    (copy / "fleet.yaml").write_text(example)
    fleet = load_fleet(copy, load_robot(project))
    assert fleet.robot_names == ["robot-1", "robot-2", "robot-3"] and set(fleet.robots[0].hosts) == {"devmachine"}
    assert [(w.name, w.robots) for w in plan_waves(fleet)] == [
        ("canary", ("robot-1",)), ("half", ("robot-2",)), ("field", ("robot-3",))]
    readme = (project / "README.md").read_text()
    assert "## Fleets" in readme and "fleet.example.yaml" in readme and "robocore schema --fleet" in readme


def test_fleet_example_gives_every_host_even_ones_yaml_would_misread(tmp_path: Path) -> None:
    from robocore.config.fleet import load_fleet

    hosts = [{"name": "on", "ip": "10.0.0.5", "user": "robot", "arch": "arm64"},
             {"name": "devmachine", "ip": "10.0.0.6", "user": "me", "arch": "amd64"}]
    copier_adapter.copy(copier_adapter.CopyRequest(template=str(TEMPLATE), destination=tmp_path / "f",
                                                   data={"hosts": hosts}, defaults=True))
    (tmp_path / "f" / "fleet.yaml").write_text((tmp_path / "f" / "fleet.example.yaml").read_text())
    fleet = load_fleet(tmp_path / "f", load_robot(tmp_path / "f"))
    assert all(set(robot.hosts) == {"on", "devmachine"} for robot in fleet.robots)


@pytest.mark.parametrize(("distro", "base", "package", "command"), [
    ("noetic", "debian", "rviz", "rviz -d /robocore/rviz/robot.rviz"),
    ("noetic", "official", "ros-noetic-rviz", "rviz -d /robocore/rviz/robot.rviz"),
    ("jazzy", "official", "ros-jazzy-rviz2", "ros2 run rviz2 rviz2 -d /robocore/rviz/robot.rviz"),
])
def test_rviz_example_draws_into_the_desktop_in_software_and_says_how_a_gpu_is_used(
        tmp_path: Path, distro: str, base: str, package: str, command: str) -> None:
    project = make(tmp_path / "viz", distro=distro, base=base)
    text = (project / "robot.yaml").read_text()
    comments = text[text.index("  # rviz in that desktop"):text.index("  # - name: rviz")]
    for recipe in ("llvmpipe", "LIBGL_ALWAYS_SOFTWARE", "nvidia: true", "NVIDIA_DRIVER_CAPABILITIES", "/dev/dri",
                   "Gazebo"):
        assert recipe in comments, recipe
    examples = uncommented_example(text, "desktop") + uncommented_example(text, "rviz")
    (project / "robot.yaml").write_text(text + "\n" + examples)
    robot = load_robot(project)
    rviz = robot.component("rviz")
    assert rviz.gui == "desktop" and robot.component("desktop").desktop is not None
    assert rviz.apt_packages == [package] and rviz.entrypoint == command
    assert rviz.environment == {"LIBGL_ALWAYS_SOFTWARE": "1"} and rviz.volumes == ["./rviz:/robocore/rviz:ro"]


def test_the_wheels_base_has_no_rviz_example_and_says_where_rviz2_is(tmp_path: Path) -> None:
    text = (make(tmp_path / "viz", distro="jazzy", base="wheels") / "robot.yaml").read_text()
    assert "  # - name: rviz" not in text
    assert "The wheels base has no rviz2 (PyPI has none): use base: official" in text


# ---------------------------------------------------------------- where init may write


def test_refuses_a_non_empty_folder_that_is_not_a_project(tmp_path: Path) -> None:
    target = tmp_path / "stuff"
    target.mkdir()
    (target / "notes.txt").write_text("mine")
    with pytest.raises(UsageError, match="not empty and is not a robocore project"):
        make(target)
    assert sorted(p.name for p in target.iterdir()) == ["notes.txt"]


def test_refuses_a_file(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("x")
    with pytest.raises(UsageError, match="not a folder"):
        make(tmp_path / "f")


def test_an_empty_existing_folder_is_fine(tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    assert load_robot(make(tmp_path / "empty")).components


def test_existing_project_keeps_edits_and_gets_missing_files_back(tmp_path: Path) -> None:
    project = make(tmp_path / "p")
    edited = (project / "robot.yaml").read_text().replace("ros_domain_id: 0", "ros_domain_id: 17")
    (project / "robot.yaml").write_text(edited)
    (project / "tasks.py").unlink()
    make(project)
    assert (project / "robot.yaml").read_text() == edited
    assert (project / "tasks.py").is_file()
    assert load_robot(project).ros_domain_id == 17


def test_an_option_is_not_taken_for_the_project_folder(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, "-m", "robocore", "init", "--help", "--defaults"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert done.stderr.splitlines()[0] == "error: --help: not a project folder (it starts with '-')"
    assert list(tmp_path.iterdir()) == []
    make(tmp_path / "-odd")  # the same name as a path is fine
    assert (tmp_path / "-odd" / "robot.yaml").is_file()


def test_dry_run_writes_nothing(tmp_path: Path) -> None:
    make(tmp_path / "dry", dry_run=True)
    assert not (tmp_path / "dry").exists()


def test_unknown_distro_or_base_is_a_usage_error(tmp_path: Path) -> None:
    with pytest.raises(UsageError, match=r"--distro 'iron'.*melodic, noetic, humble, jazzy, kilted, rolling"):
        make(tmp_path / "a", distro="iron")
    with pytest.raises(UsageError, match=r"--base 'docker'.*official, wheels"):
        make(tmp_path / "b", base="docker")
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_without_defaults_and_without_a_terminal_init_says_so(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sys, "stdin", io.StringIO(""))
    with pytest.raises(UsageError, match="not a terminal") as caught:
        init.run(tmp_path / "x", defaults=False, distro=None, base=None, dry_run=False)
    assert "--defaults" in (caught.value.hint or "")


def test_missing_template_is_named(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(copier_adapter.TEMPLATE_ENV, str(tmp_path / "nowhere"))
    with pytest.raises(UsageError, match=f"{copier_adapter.TEMPLATE_ENV} .*nowhere: no such folder"):
        make(tmp_path / "x")
    assert not (tmp_path / "x").exists()


def test_cli_init_and_its_errors(tmp_path: Path) -> None:
    robocore = [sys.executable, "-m", "robocore"]
    ok = subprocess.run([*robocore, "init", str(tmp_path / "cli"), "--defaults", "--base", "wheels"],
                        capture_output=True, text=True, timeout=120)
    assert ok.returncode == 0, ok.stderr
    assert load_robot(tmp_path / "cli").base.kind.value == "wheels"
    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / "a").write_text("a")
    bad = subprocess.run([*robocore, "init", str(tmp_path / "junk"), "--defaults"],
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2
    assert bad.stderr.splitlines()[0] == f"error: {tmp_path / 'junk'}: folder is not empty and is not a robocore " \
                                         "project (no robot.yaml)"
    assert "Traceback" not in bad.stderr


def test_plain_copier_copy_makes_a_valid_project(tmp_path: Path) -> None:
    copier = shutil.which("copier", path=str(Path(sys.executable).parent)) or shutil.which("copier")
    assert copier, "copier's command line must be installed with robocore"
    subprocess.run([copier, "copy", "--defaults", "--data", "base_kind=wheels", str(TEMPLATE), str(tmp_path / "c")],
                   check=True, capture_output=True, timeout=120)
    robot = load_robot(tmp_path / "c")
    assert robot.base.kind.value == "wheels" and robot.hosts[0].name == "devmachine"
    assert robot.hosts[0].user == Path("~").expanduser().name


# ---------------------------------------------------------------- copier update


def test_update_of_a_project_without_answers_is_refused(tmp_path: Path) -> None:
    with pytest.raises(UsageError, match=r"\.copier-answers\.yml: missing"):
        copier_adapter.update(tmp_path)


# ---------------------------------------------------------------- the example packages


@pytest.mark.parametrize(("component", "package"), sorted(PACKAGES.items()))
def test_example_package_is_a_valid_ament_python_package(project: Path, component: str, package: str) -> None:
    root = project / "components" / component / "src" / package
    manifest = ET.parse(root / "package.xml").getroot()
    assert manifest.tag == "package" and manifest.get("format") == "3"
    assert manifest.findtext("name") == package
    assert manifest.findtext("export/build_type") == "ament_python"
    assert {e.text for e in manifest.findall("exec_depend")} == {"rclpy", "std_msgs"}
    for tag in ["version", "description", "maintainer", "license"]:
        assert (manifest.findtext(tag) or "").strip(), tag
    assert (root / "resource" / package).is_file()
    assert (root / package / "__init__.py").is_file()
    cfg = (root / "setup.cfg").read_text()
    assert f"install_scripts=$base/lib/{package}" in cfg and f"script_dir=$base/lib/{package}" in cfg

    setup = ast.parse((root / "setup.py").read_text())
    call = next(n for n in ast.walk(setup) if isinstance(n, ast.Call) and getattr(n.func, "id", "") == "setup")
    assert isinstance(setup.body[1], ast.Assign)
    names = {"package_name": ast.literal_eval(setup.body[1].value)}
    assert names["package_name"] == package
    keywords = {k.arg: k.value for k in call.keywords}
    scripts = ast.literal_eval(keywords["entry_points"])["console_scripts"]
    assert scripts == [f"{component} = {package}.{component}:main"]
    module = ast.parse((root / package / f"{component}.py").read_text())
    assert "main" in {n.name for n in module.body if isinstance(n, ast.FunctionDef)}


class FakeNode:
    """Just enough of rclpy.node.Node to drive the example nodes without ROS."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.timers: list[tuple[float, Callable[[], None]]] = []
        self.published: list[tuple[str, str]] = []
        self.subscriptions: list[tuple[str, Callable[[Any], None]]] = []
        self.listeners = 0  # what the publishers' get_subscription_count() says

    def create_publisher(self, msg_type: type, topic: str, qos: int) -> Any:
        node = self
        return types.SimpleNamespace(publish=lambda msg: node.published.append((topic, msg.data)),
                                     get_subscription_count=lambda: node.listeners)

    def create_timer(self, period: float, callback: Callable[[], None]) -> tuple[float, Callable[[], None]]:
        self.timers.append((period, callback))
        return self.timers[-1]

    def destroy_timer(self, timer: tuple[float, Callable[[], None]]) -> None:
        self.timers.remove(timer)

    def create_subscription(self, msg_type: type, topic: str, callback: Callable[[Any], None], qos: int) -> None:
        self.subscriptions.append((topic, callback))


@pytest.fixture()
def fake_ros(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    class String:
        def __init__(self) -> None:
            self.data = ""

    modules = {
        "rclpy": types.ModuleType("rclpy"),
        "rclpy.node": types.ModuleType("rclpy.node"),
        "rclpy.executors": types.ModuleType("rclpy.executors"),
        "std_msgs": types.ModuleType("std_msgs"),
        "std_msgs.msg": types.ModuleType("std_msgs.msg"),
    }
    modules["rclpy.node"].Node = FakeNode  # type: ignore[attr-defined]
    modules["rclpy.executors"].ExternalShutdownException = RuntimeError  # type: ignore[attr-defined]
    modules["std_msgs.msg"].String = String  # type: ignore[attr-defined]
    for name, module in modules.items():
        monkeypatch.setitem(sys.modules, name, module)
    yield


def load_node_module(project: Path, component: str) -> Any:
    package = PACKAGES[component]
    path = project / "components" / component / "src" / package / package / f"{component}.py"
    namespace: dict[str, Any] = {"__name__": f"{package}.{component}"}
    exec(compile(path.read_text(), str(path), "exec"), namespace)
    return types.SimpleNamespace(**namespace)


def test_talker_publishes_a_counting_greeting_every_half_second(project: Path, fake_ros: None) -> None:
    talker = load_node_module(project, "talker").Talker()
    assert talker.name == "talker"
    [(look, first)] = talker.timers
    assert look < 0.05
    first()
    first()
    assert talker.published == [] and len(talker.timers) == 1  # nobody listens yet: it looks again
    talker.listeners = 1
    out = io.StringIO()
    with redirect_stdout(out):
        first()  # the first greeting as soon as someone listens
        [(period, tick)] = talker.timers
        assert period == 0.5
        tick()
        tick()
    assert talker.published == [("chatter", f"hello from talker #{n}") for n in (1, 2, 3)]
    assert out.getvalue().splitlines() == [f"Publishing: hello from talker #{n}" for n in (1, 2, 3)]


def test_a_talker_nobody_listens_to_starts_after_its_longest_wait(project: Path, fake_ros: None) -> None:
    module = load_node_module(project, "talker")
    talker = module.Talker()
    [(look, first)] = talker.timers
    assert 0.5 < module.FIRST_WAIT <= 5  # past discovery on a busy machine, and not long without a greeting
    with redirect_stdout(io.StringIO()):
        for _ in range(round(module.FIRST_WAIT / look) - 1):
            first()
        assert talker.published == []
        first()
    assert talker.published == [("chatter", "hello from talker #1")]
    assert [period for period, _ in talker.timers] == [0.5]


def test_listener_prints_what_it_hears(project: Path, fake_ros: None) -> None:
    listener = load_node_module(project, "listener").Listener()
    [(topic, heard)] = listener.subscriptions
    assert topic == "chatter"
    out = io.StringIO()
    with redirect_stdout(out):
        heard(types.SimpleNamespace(data="hello from talker #7"))
    assert out.getvalue() == "I heard: hello from talker #7\n"
