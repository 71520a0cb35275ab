"""The dev-shell plan: mounts, environment, user, devices, GPUs, X11/Wayland, exec argv (no Docker)."""

from __future__ import annotations

import subprocess
from importlib import resources
from pathlib import Path

import pytest

from robocore.adapters import x11
from robocore.plan import devshell as plan
from robocore.plan import naming
from robocore.plan.discovery import fastdds as dds
from robocore.project import Project

ROBOT = """\
ros_distro: jazzy
ros_domain_id: 7
image_prefix: "acme-"
hosts:
  - name: dev
    ip: 127.0.0.1
components:
  - name: arm
    runs_on: dev
    folder: components/arm
    devices: ["/dev/robocore-absent-tty", "/dev/video0:/dev/cam:r"]
    environment: {ARM_MODE: sim}
    volumes: ["maps:/maps:ro", "/nonexistent/robocore-test:/data"]
    nvidia: true
    privileged: true
  - name: viz
    runs_on: dev
    image: osrf/ros:jazzy-desktop
"""

SUPER = {"ROS_SUPER_CLIENT": "TRUE", "ROS_DISCOVERY_SERVER": "127.0.0.1:11811", "ROS_DOMAIN_ID": "7"}


@pytest.fixture
def project(make_project) -> Project:
    return Project.load(make_project(ROBOT, folders=["components/arm", "maps"]))


def shell(project: Project, component: str = "arm", *, machine: plan.DevMachine | None = None,
          dds_env: dict[str, str] | None = None, **request: object) -> plan.ShellSpec:
    machine = machine or plan.DevMachine(uid=1000, gid=1000, user="alice")
    return plan.plan_shell(project, plan.ShellRequest(component=component, **request), machine,  # type: ignore[arg-type]
                           dds_env=SUPER if dds_env is None else dds_env)


def mounts(spec: plan.ShellSpec) -> dict[str, plan.Mount]:
    return {m.target: m for m in spec.mounts}


def test_workspace_build_folders_home_and_shell_files_are_mounted(project: Project) -> None:
    spec = shell(project)
    by_target = mounts(spec)
    state = project.root / ".robocore"
    assert by_target[naming.CONTAINER_WS] == plan.Mount(str(project.root / "components/arm"), naming.CONTAINER_WS)
    assert by_target[naming.CONTAINER_INSTALL].source == str(state / "build/arm/install")
    assert by_target[plan.CONTAINER_BUILD].source == str(state / "build/arm/build")
    assert by_target[plan.CONTAINER_LOG].source == str(state / "build/arm/log")
    assert by_target["/home/alice"] == plan.Mount(str(state / "home/alice"), "/home/alice")
    assert by_target[plan.CONTAINER_SHELL] == plan.Mount(str(state / "shell"), plan.CONTAINER_SHELL, read_only=True)
    assert by_target[naming.CONTAINER_DDS] == plan.Mount(str(state / "dds"), naming.CONTAINER_DDS, read_only=True)
    assert not any(m.read_only for t, m in by_target.items() if t in (naming.CONTAINER_WS, "/home/alice"))
    assert spec.workdir == naming.CONTAINER_WS
    assert spec.name == naming.shell_container_name(project.name, "arm")
    assert spec.image == "acme-arm:latest"
    assert spec.network_mode == "host" and spec.ipc_mode == "host"


def test_component_volumes_are_mounted_relative_to_the_project(project: Project) -> None:
    spec = shell(project)
    assert mounts(spec)["/maps"] == plan.Mount(str(project.root / "maps"), "/maps", read_only=True)
    spec = plan.plan_shell(project, plan.ShellRequest("arm"), plan.DevMachine(uid=1, gid=1),
                           existing_paths=frozenset({str(project.root / "maps")}))
    assert "/maps" in mounts(spec) and "/data" not in mounts(spec)
    assert any("/nonexistent/robocore-test" in note for note in spec.notes)


def test_image_component_has_no_workspace_and_starts_in_home(project: Project) -> None:
    spec = shell(project, "viz")
    assert spec.image == "osrf/ros:jazzy-desktop"
    assert naming.CONTAINER_WS not in mounts(spec)
    assert naming.CONTAINER_INSTALL not in mounts(spec)
    assert "COLCON_DEFAULTS_FILE" not in spec.environment
    assert spec.workdir == "/home/alice"


def test_environment_is_super_client_plus_component_and_user(project: Project) -> None:
    spec = shell(project)
    env = spec.environment
    for key, value in SUPER.items():
        assert env[key] == value
    assert env["ARM_MODE"] == "sim"
    assert env["ROBOCORE_UID"] == "1000" and env["ROBOCORE_GID"] == "1000"
    assert env["ROBOCORE_USER"] == "alice" and env["ROBOCORE_HOME"] == "/home/alice"
    assert env["ROBOCORE_CONTAINER"] == spec.name and env["ROBOCORE_COMPONENT"] == "arm"
    assert env["COLCON_DEFAULTS_FILE"] == f"{plan.CONTAINER_SHELL}/colcon-defaults.yaml"
    assert spec.session_env["HOME"] == "/home/alice" and spec.session_env["USER"] == "alice"


def test_without_dds_module_only_the_domain_is_set(project: Project) -> None:
    spec = plan.plan_shell(project, plan.ShellRequest("arm"), plan.DevMachine(uid=1, gid=1), dds_env=None)
    assert spec.environment["ROS_DOMAIN_ID"] == "7"
    assert "ROS_SUPER_CLIENT" not in spec.environment
    assert naming.CONTAINER_DDS not in mounts(spec)


def test_real_dds_module_gives_a_super_client(project: Project) -> None:
    env = dds.client_environment(project.robot, super_client=True)
    spec = shell(project, dds_env=env)
    assert spec.environment["ROS_SUPER_CLIENT"].lower() in ("true", "1")
    assert spec.environment["ROS_DISCOVERY_SERVER"].startswith("127.0.0.1:")


@pytest.mark.parametrize(
    ("raw", "uid", "expected"),
    [("alice", 1000, "alice"), (None, 1000, "dev"), ("Bad Name", 1000, "dev"), ("root", 1000, "dev"),
     ("alice", 0, "root"), ("x" * 40, 5, "dev")],
)
def test_user_name(raw: str | None, uid: int, expected: str) -> None:
    assert plan.user_name(raw, uid) == expected


def test_root_developer_gets_root_user_with_a_persistent_home(project: Project) -> None:
    spec = shell(project, machine=plan.DevMachine(uid=0, gid=0, user="root"))
    assert spec.user == "root" and spec.home == "/home/root"
    assert mounts(spec)["/home/root"].source.endswith(".robocore/home/root")


def test_component_devices_are_passed_and_devices_all_mounts_dev(project: Project) -> None:
    spec = shell(project)
    assert spec.devices == ("/dev/robocore-absent-tty", "/dev/video0:/dev/cam:r")
    assert "/dev" not in mounts(spec) and not spec.device_cgroup_rules
    spec = shell(project, devices_all=True)
    assert mounts(spec)["/dev"] == plan.Mount("/dev", "/dev")
    assert spec.devices == ()
    assert set(spec.device_cgroup_rules) == {"c *:* rmw", "b *:* rmw"}
    assert plan.device_paths(project.component("arm"), devices_all=False) == ["/dev/robocore-absent-tty", "/dev/video0"]


def test_device_groups_reach_the_setup_script(project: Project) -> None:
    spec = shell(project, machine=plan.DevMachine(uid=1000, gid=1000, device_gids=(20, 44, 20)))
    assert spec.environment["ROBOCORE_EXTRA_GIDS"] == "20 44"


def test_parse_device() -> None:
    tty = "/dev/robocore-absent-tty"
    assert plan.parse_device(tty) == (tty, tty, "rwm")
    assert plan.parse_device("/dev/video0:/dev/cam:r") == ("/dev/video0", "/dev/cam", "r")


@pytest.mark.parametrize(
    ("runtime", "flag", "expected"),
    [(True, None, True), (False, None, False), (False, True, True), (True, False, False)],
)
def test_gpus_follow_the_runtime_unless_forced(project: Project, runtime: bool, flag: bool | None,
                                               expected: bool) -> None:
    spec = shell(project, machine=plan.DevMachine(uid=1, gid=1, nvidia_runtime=runtime), gpus=flag)
    assert spec.gpus is expected
    assert ("NVIDIA_DRIVER_CAPABILITIES" in spec.environment) is expected


def test_nvidia_component_without_runtime_gets_a_note(project: Project) -> None:
    spec = shell(project, machine=plan.DevMachine(uid=1, gid=1, nvidia_runtime=False))
    assert any("NVIDIA" in note for note in spec.notes)


def test_privileged_only_on_request(project: Project) -> None:
    spec = shell(project)  # the component is privileged on the robot, but nobody asked here
    assert spec.privileged is False
    assert spec.container_kwargs()["privileged"] is False
    assert any("--privileged" in note for note in spec.notes)
    assert shell(project, privileged=True).container_kwargs()["privileged"] is True


def test_x11_present(project: Project) -> None:
    machine = plan.DevMachine(uid=1000, gid=1000, user="alice", display=":1", x11_sockets=True)
    spec = shell(project, machine=machine)
    by_target = mounts(spec)
    assert by_target["/tmp/.X11-unix"] == plan.Mount("/tmp/.X11-unix", "/tmp/.X11-unix", read_only=True)
    assert by_target[plan.CONTAINER_X11].source == str(project.root / ".robocore/x11" / spec.name)
    assert by_target[plan.CONTAINER_X11].read_only
    assert spec.environment["QT_X11_NO_MITSHM"] == "1"
    assert spec.session_env["DISPLAY"] == ":1"
    assert spec.session_env["XAUTHORITY"] == f"{plan.CONTAINER_X11}/{plan.XAUTH_FILE}"


def test_x11_absent_is_quietly_headless(project: Project) -> None:
    spec = shell(project)
    assert "/tmp/.X11-unix" not in mounts(spec) and plan.CONTAINER_X11 not in mounts(spec)
    assert "DISPLAY" not in spec.session_env and "DISPLAY" not in spec.environment
    assert "QT_X11_NO_MITSHM" not in spec.environment
    assert not spec.notes or all("display" not in n.lower() for n in spec.notes)


def test_tcp_display_without_socket_folder_still_gets_the_cookie(project: Project) -> None:
    spec = shell(project, machine=plan.DevMachine(uid=1, gid=1, display="localhost:10.0", x11_sockets=False))
    assert "/tmp/.X11-unix" not in mounts(spec)
    assert spec.session_env["DISPLAY"] == "localhost:10.0"
    assert plan.CONTAINER_X11 in mounts(spec)


def test_wayland_socket(project: Project) -> None:
    machine = plan.DevMachine(uid=1000, gid=1000, wayland_socket="/run/user/1000/wayland-0")
    spec = shell(project, machine=machine)
    assert mounts(spec)[f"{plan.CONTAINER_XDG}/wayland-0"].source == "/run/user/1000/wayland-0"
    assert spec.session_env["WAYLAND_DISPLAY"] == "wayland-0"
    assert spec.session_env["XDG_RUNTIME_DIR"] == plan.CONTAINER_XDG
    assert "WAYLAND_DISPLAY" not in shell(project).session_env


def test_new_containers_are_numbered(project: Project) -> None:
    assert shell(project, number=2).name == naming.shell_container_name(project.name, "arm", 2)
    assert shell(project, number=2).name != shell(project).name


def test_fingerprint_ignores_the_session_but_not_the_container(project: Project) -> None:
    base = shell(project)
    same = shell(project, machine=plan.DevMachine(uid=1000, gid=1000, user="alice", term="xterm"))
    assert base.labels[naming.LABEL_SPEC] == same.labels[naming.LABEL_SPEC]
    for other in (shell(project, devices_all=True), shell(project, gpus=True),
                  shell(project, machine=plan.DevMachine(uid=1001, gid=1000, user="alice")),
                  shell(project, machine=plan.DevMachine(uid=1000, gid=1000, user="alice", display=":0"))):
        assert other.labels[naming.LABEL_SPEC] != base.labels[naming.LABEL_SPEC]


def test_labels(project: Project) -> None:
    labels = shell(project).labels
    assert labels[naming.LABEL_PROJECT] == project.name
    assert labels[naming.LABEL_COMPONENT] == "arm"
    assert labels[naming.LABEL_ROLE] == "shell"


def test_container_kwargs_start_as_root_running_the_setup_script(project: Project) -> None:
    spec = shell(project, devices_all=True)
    kwargs = spec.container_kwargs()
    assert kwargs["user"] == "0:0"
    assert kwargs["entrypoint"] == ["/bin/sh", f"{plan.CONTAINER_SHELL}/setup.sh"]
    assert kwargs["network_mode"] == "host" and kwargs["ipc_mode"] == "host"
    assert {"Type": "bind", "Source": "/dev", "Target": "/dev", "ReadOnly": False} in kwargs["mounts"]
    assert kwargs["device_cgroup_rules"] == list(spec.device_cgroup_rules)
    assert kwargs["labels"] == dict(spec.labels)
    assert "devices" not in kwargs


def test_exec_argv_interactive_and_command(project: Project) -> None:
    spec = shell(project, machine=plan.DevMachine(uid=1000, gid=1000, user="alice", display=":1", term="xterm"))
    interactive = plan.exec_argv(spec, cmd=None, stdin_tty=True)
    assert interactive[:3] == ["docker", "exec", "-it"]
    assert interactive[-3:] == [spec.name, "bash", "-l"]
    i = interactive.index("-u")
    assert interactive[i + 1] == "1000"  # numeric UID: Docker applies the user's groups
    assert interactive[interactive.index("-w") + 1] == naming.CONTAINER_WS
    assert "DISPLAY=:1" in interactive and "TERM=xterm" in interactive
    command = plan.exec_argv(spec, cmd="xdpyinfo | head -1", stdin_tty=True)
    assert "-t" not in command and "-it" not in command and "-i" not in command
    assert command[-3:] == ["bash", "-lc", "xdpyinfo | head -1"]
    # robocore on a terminal: the command gets one too (`--cmd tmux`, as hand-made run scripts allow)
    tmux = plan.exec_argv(spec, cmd="tmux", stdin_tty=True, stdout_tty=True)
    assert tmux[:3] == ["docker", "exec", "-it"] and tmux[-3:] == ["bash", "-lc", "tmux"]
    assert "TERM=xterm" in tmux
    # output redirected: no TTY, so the output keeps plain line ends
    redirected = plan.exec_argv(spec, cmd="ros2 topic list", stdin_tty=True, stdout_tty=False)
    assert "-it" not in redirected and "-t" not in redirected
    # input piped in: stdin attached, no TTY, whatever stdout is
    assert plan.exec_argv(spec, cmd="cat", stdin_tty=False, stdout_tty=True)[2] == "-i"
    piped = plan.exec_argv(spec, cmd="cat", stdin_tty=False)
    assert "-i" in piped and "-it" not in piped
    assert plan.exec_argv(spec, cmd=None, stdin_tty=False)[2] == "-i"


def test_describe_is_json_friendly(project: Project) -> None:
    import json

    text = json.dumps(plan.describe(shell(project)))
    assert "acme-arm:latest" in text


# --- xauth cookie rewriting --------------------------------------------------------------

NLIST = (
    "0100 0002 766d 0002 3737 0012 4d49542d4d414749432d434f4f4b49452d31 0010 939120eaa65ed6a8f33988d381ecea5b\n"
    "0000 0004 7f000001 0001 31 0012 4d49542d4d414749432d434f4f4b49452d31 0010 00112233445566778899aabbccddeeff\n"
)


def test_wildcard_entries_rewrite_only_the_family() -> None:
    out = x11.wildcard_entries(NLIST).splitlines()
    assert len(out) == 2
    for original, rewritten in zip(NLIST.splitlines(), out, strict=True):
        assert rewritten.split()[0] == "ffff"
        assert rewritten.split()[1:] == original.split()[1:]
    assert x11.wildcard_entries("") == ""


@pytest.mark.parametrize(
    ("display", "number", "local"),
    [(":0", 0, True), (":1.0", 1, True), ("unix:3", 3, True), ("localhost:10.0", 10, False), ("garbage", None, False)],
)
def test_display_parsing(display: str, number: int | None, local: bool) -> None:
    assert x11.display_number(display) == number
    assert x11.is_local_display(display) is local


def test_cookie_file_round_trip(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    source = tmp_path / "host.auth"
    subprocess.run(["xauth", "-q", "-f", str(source), "add", ":42", ".", "0123456789abcdef0123456789abcdef"],
                   check=True, capture_output=True)
    monkeypatch.setenv("XAUTHORITY", str(source))
    assert x11.write_cookie_file(":42", tmp_path / "c", file_name="xauth")
    listed = subprocess.run(["xauth", "-f", str(tmp_path / "c" / "xauth"), "nlist"], capture_output=True, text=True,
                            check=True).stdout
    assert listed.split()[0] == "ffff"
    assert listed.split()[-1] == "0123456789abcdef0123456789abcdef"
    assert (tmp_path / "c" / "xauth").stat().st_mode & 0o777 == 0o600
    assert not x11.write_cookie_file(":43", tmp_path / "d")  # no cookie for that display


# --- the shell files ---------------------------------------------------------------------


def _resource(name: str) -> str:
    return resources.files("robocore.resources").joinpath("shell", name).read_text()


def test_shell_files_exist() -> None:
    """Every file the plan mounts is in the package and says something, and the package holds no other."""
    folder = resources.files("robocore.resources").joinpath("shell")
    assert sorted(plan.SHELL_FILES) == sorted(entry.name for entry in folder.iterdir() if entry.is_file())
    assert all(_resource(name).strip() for name in plan.SHELL_FILES)


def test_bashrc_has_the_seed_shortcuts_and_a_component_prompt() -> None:
    text = _resource("bashrc")
    for alias in ("cb=", "cbp=", "cbt=", "run='ros2 run'", "launch='ros2 launch'", "topic='ros2 topic'",
                  "node='ros2 node'", "param='ros2 param'", "ll=", "la="):
        assert f"alias {alias}" in text
    assert "ROBOCORE_CONTAINER" in text.split("PS1=", 1)[1].splitlines()[0]


@pytest.mark.parametrize(("interpreter", "name"), [("sh", "setup.sh"), ("sh", "profile.sh"), ("bash", "bashrc")])
def test_shell_files_parse(tmp_path: Path, interpreter: str, name: str) -> None:
    path = tmp_path / name
    path.write_text(_resource(name))
    done = subprocess.run([interpreter, "-n", str(path)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def test_colcon_defaults_match_the_mounts() -> None:
    import yaml

    defaults = yaml.safe_load(_resource("colcon-defaults.yaml"))
    assert defaults["build"]["base-paths"] == [naming.CONTAINER_WS]
    assert defaults["build"]["build-base"] == plan.CONTAINER_BUILD
    assert defaults["build"]["install-base"] == naming.CONTAINER_INSTALL


# --- the command in --dry-run (no Docker) ------------------------------------------------


def test_dry_run_prints_the_plan_without_docker(project: Project, monkeypatch: pytest.MonkeyPatch,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    import json

    from robocore.commands import shell
    from robocore.commands.support.context import Options

    monkeypatch.setenv("DOCKER_HOST", "unix:///nonexistent/docker.sock")  # would fail if contacted
    monkeypatch.setenv("ROBOCORE_UID", "1234")
    monkeypatch.delenv("ROBOCORE_GID", raising=False)
    monkeypatch.setenv("USER", "carol")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    code = shell.run(Options(project_dir=project.root, dry_run=True), component="viz", cmd="true", new=False,
                        devices="all", gpus=None, privileged=False)
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert out["user"] == "carol (1234:1234)"
    assert out["image"] == "osrf/ros:jazzy-desktop"
    assert "/dev:/dev" in out["mounts"]
    assert out["exec"][-3:] == ["bash", "-lc", "true"]
    assert out["environment"]["ROS_SUPER_CLIENT"] == "TRUE"
    assert not (project.root / ".robocore" / "shell").exists()  # a dry run writes nothing


def test_devices_flag_only_takes_all(project: Project) -> None:
    from robocore.commands import shell
    from robocore.commands.support.context import Options
    from robocore.errors import UsageError

    with pytest.raises(UsageError, match="--devices"):
        shell.run(Options(project_dir=project.root, dry_run=True), component="viz", cmd=None, new=False,
                     devices="/dev/robocore-absent-tty", gpus=None, privileged=False)


def test_missing_component_device_is_a_usage_error(project: Project, monkeypatch: pytest.MonkeyPatch) -> None:
    from robocore.commands import shell
    from robocore.commands.support.context import Options
    from robocore.errors import UsageError

    with pytest.raises(UsageError, match="device /dev/robocore-absent-tty does not exist"):
        shell.run(Options(project_dir=project.root, dry_run=True), component="arm", cmd=None, new=False,
                     devices=None, gpus=None, privileged=False)


def test_the_shell_runs_the_image_of_its_components_host_arch(make_project) -> None:
    amd = Project.load(make_project(ROBOT, folders=["components/arm", "maps"]))
    arm = Project.load(make_project(ROBOT.replace("    ip: 127.0.0.1\n", "    ip: 127.0.0.1\n    arch: arm64\n"),
                                    folders=["components/arm", "maps"]))
    amd_spec, arm_spec = shell(amd), shell(arm)
    assert amd_spec.container_kwargs()["platform"] == "linux/amd64"
    assert arm_spec.container_kwargs()["platform"] == "linux/arm64"  # emulated on an amd64 desk, native on arm64
    assert amd_spec.fingerprint() != arm_spec.fingerprint()  # a shell of the other arch is never reused
