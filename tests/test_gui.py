"""GUI components as data: desktop and gui settings, their validation, container specs, the host cookie script,
and the discovery address of bridge containers."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest
import yaml

from robocore.commands.support.displays import prepare_host_displays
from robocore.config.desktop import Desktop, display_host
from robocore.config.loader import parse_robot_text, robot_warnings
from robocore.config.model import Robot
from robocore.errors import ConfigError, UsageError
from robocore.plan import addresses, gui
from robocore.plan.compose import compose_document
from robocore.plan.containers import component_spec
from robocore.project import Project

ROOT = Path("/srv/myrobot")
DESKTOP_APT = ["tigervnc-standalone-server", "tigervnc-tools", "novnc", "websockify", "openbox"]


def project(components: list[dict[str, Any]], *, root: Path = ROOT, dev_ip: str = "192.168.1.10") -> Project:
    robot = Robot.model_validate({
        "ros_distro": "jazzy",
        "hosts": [{"name": "dev", "ip": dev_ip, "docker": "local"}, {"name": "pi", "ip": "192.168.1.20", "user": "pi"}],
        "components": components,
    })
    return Project(root=root, robot=robot)


def desktop(**changes: Any) -> dict[str, Any]:
    return {"name": "vnc", "runs_on": "dev", "desktop": {}, "apt_packages": DESKTOP_APT, **changes}


def spec_of(p: Project, name: str) -> Any:
    return component_spec(p, p.robot.component(name))


# ------------------------------------------------------------------ the model


def test_desktop_defaults_and_ports() -> None:
    d = Desktop()
    assert (d.display, d.size, d.web_port, d.rfb_port, d.local_only) == (1, "1280x800", 6080, 5901, False)
    assert Desktop(display=7).rfb_port == 5907
    assert Desktop(display=7, vnc_port=5999).rfb_port == 5999


@pytest.mark.parametrize(("display", "host"), [(":0", ""), ("unix:1", ""), (":1.0", ""), ("laptop:0", "laptop"),
                                               ("localhost:10.0", "localhost"), ("no display", None)])
def test_display_host(display: str, host: str | None) -> None:
    assert display_host(display) == host


# ------------------------------------------------------------------ validation: one line each, file:line: key

HEAD = """\
ros_distro: jazzy
hosts:
  - {name: dev, ip: 192.168.1.10}
  - {name: pi, ip: 192.168.1.20}
components:
  - name: vnc
    runs_on: dev
    desktop: {display: 1}
    apt_packages: [tigervnc-standalone-server, tigervnc-tools, novnc, websockify]
"""


def problems(tail: str, head: str = HEAD) -> list[str]:
    try:
        parse_robot_text(head + tail, file="robot.yaml")
    except ConfigError as error:
        return error.lines()
    return []


def test_a_gui_component_of_the_desktops_host_is_valid() -> None:
    assert problems("  - name: viz\n    runs_on: dev\n    gui: vnc\n") == []
    assert problems("  - name: viz\n    runs_on: pi\n    gui: true\n    environment: {DISPLAY: ':1'}\n") == []


@pytest.mark.parametrize(("tail", "expected"), [
    ("  - name: viz\n    runs_on: pi\n    gui: vnc\n",
     "robot.yaml:12: components[1].gui: desktop 'vnc' runs on 'dev' and viz on 'pi': X does not cross hosts; "
     "run viz on 'dev', or give 'pi' a desktop of its own"),
    ("  - name: viz\n    runs_on: dev\n    gui: true\n    environment: {DISPLAY: 'laptop:0'}\n",
     "robot.yaml:13: components[1].environment.DISPLAY: 'laptop:0' sends X over the network to 'laptop', which "
     "robocore does not do; use this host's own display (':0') or a desktop component on this host (gui: <name>)"),
    ("  - name: viz\n    runs_on: dev\n    gui: true\n    environment: {DISPLAY: '-display'}\n",
     "robot.yaml:13: components[1].environment.DISPLAY: '-display' is not an X display of this host, such as ':0' "
     "or ':1'"),
    ("  - name: viz\n    runs_on: dev\n    gui: vcn\n",
     "robot.yaml:12: components[1].gui: unknown component 'vcn' (known: vnc, viz); did you mean 'vnc'?"),
    ("  - name: viz\n    runs_on: dev\n    gui: viz\n",
     "robot.yaml:12: components[1].gui: 'viz' is not a desktop component (desktops: vnc); use gui: true for the "
     "host's own display"),
    ("  - name: viz\n    runs_on: dev\n    gui: 5\n",
     "robot.yaml:12: components[1].gui: must be true, false or the name of a desktop component (got 5)"),
    ("  - name: viz\n    runs_on: dev\n    gui: vnc\n    environment: {DISPLAY: ':0'}\n",
     "robot.yaml:13: components[1].environment.DISPLAY: gui: vnc sets DISPLAY to that desktop's display; remove "
     "DISPLAY from environment"),
    ("  - name: vnc2\n    runs_on: dev\n    desktop: {web_port: 6081, vnc_port: 5999}\n"
     "    apt_packages: [tigervnc-standalone-server, tigervnc-tools, novnc, websockify]\n",
     "robot.yaml:12: components[1].desktop.display: display 1 is already used by the desktop of components[0] on "
     "'dev'"),
    ("  - name: vnc2\n    runs_on: dev\n    desktop: {display: 2, web_port: 6082}\n    entrypoint: xterm\n"
     "    apt_packages: [tigervnc-standalone-server, tigervnc-tools, novnc/bookworm, websockify=0.10.0+dfsg1-4+b1]\n",
     "robot.yaml:13: components[1].entrypoint: robocore starts the desktop (Xvnc, window manager, noVNC); remove it"),
])
def test_gui_problems_are_one_line_with_file_line_and_key(tail: str, expected: str) -> None:
    found = problems(tail)
    assert found == [expected]


def test_a_desktop_without_its_packages_or_with_gui_is_refused() -> None:
    packages = "    apt_packages: [tigervnc-standalone-server, tigervnc-tools, novnc, websockify]\n"
    head = HEAD.replace(packages, "    apt_packages: [novnc]\n")
    assert problems("", head) == [
        "robot.yaml:9: components[0].apt_packages: a desktop needs tigervnc-standalone-server, novnc, websockify, "
        "tigervnc-tools (missing: tigervnc-standalone-server, websockify, tigervnc-tools); a window manager such as "
        "openbox is optional; tigervnc-tools gives vncpasswd, for the desktop's password"]
    # an open desktop (no password) needs no vncpasswd
    open_desk = HEAD.replace(packages, "    apt_packages: [tigervnc-standalone-server, novnc, websockify]\n").replace(
        "desktop: {display: 1}", "desktop: {display: 1, open: true}")
    assert problems("", open_desk) == []
    # a pre-built image brings its own packages
    image = HEAD.replace(packages, "    image: my/desk:1\n")
    assert problems("", image) == []
    assert problems("", HEAD + "    gui: true\n") == [
        "robot.yaml:10: components[0].gui: a desktop component shows the windows of others; remove gui"]


def test_only_a_desktop_opened_in_robot_yaml_is_warned_about(tmp_path: Path) -> None:
    # the default asks for the project's password: nothing to warn about, on every interface or not
    assert robot_warnings(tmp_path / "robot.yaml", parse_robot_text(HEAD)) == []
    opened = parse_robot_text(HEAD.replace("desktop: {display: 1}", "desktop: {display: 1, open: true}"))
    (warning,) = robot_warnings(tmp_path / "robot.yaml", opened)
    text = str(warning)
    assert "components[0].desktop.open: warning:" in text and "port 6080 of every interface of dev" in text
    assert "without a password" in text
    local = parse_robot_text(HEAD.replace("desktop: {display: 1}",
                                          "desktop: {display: 1, open: true, local_only: true}"))
    (warning,) = robot_warnings(tmp_path / "robot.yaml", local)
    assert "port 6080 of 127.0.0.1 of dev" in str(warning)


# ------------------------------------------------------------------ container specs


def test_desktop_component_runs_robocores_desktop_script_with_its_own_socket_volume() -> None:
    p = project([desktop(desktop={"display": 3, "size": "800x600", "local_only": True})])
    spec = spec_of(p, "vnc")
    assert spec.command == ("bash", "-c", gui.desktop_script(), "robocore-desktop")
    assert "Xvnc" in spec.command[2] and "websockify" in spec.command[2]
    env = spec.env
    assert env["ROBOCORE_DESKTOP_DISPLAY"] == "3" and env["ROBOCORE_DESKTOP_VNC_PORT"] == "5903"
    assert env["ROBOCORE_DESKTOP_SIZE"] == "800x600" and env["ROBOCORE_DESKTOP_LISTEN"] == "127.0.0.1"
    assert env["ROBOCORE_DESKTOP_XAUTHORITY"] == "/tmp/.X11-unix/xauth"
    (volume,) = [m for m in spec.mounts if m.target == "/tmp/.X11-unix"]
    assert volume.source == "myrobot-vnc-x11" and volume.is_named_volume and not volume.read_only
    assert spec.network_mode == "host"
    assert project([desktop()]).robot.component("vnc").desktop is not None
    assert spec_of(project([desktop()]), "vnc").env["ROBOCORE_DESKTOP_LISTEN"] == "0.0.0.0"


def test_a_desktop_mounts_the_projects_password_file_read_only_and_gets_only_its_path() -> None:
    p = project([desktop(), desktop(name="pidesk", runs_on="pi")])
    local = spec_of(p, "vnc")
    assert local.env["ROBOCORE_DESKTOP_PASSWORD_FILE"] == gui.PASSWORD_MOUNT == "/run/robocore-desktop/vnc-password"
    (secret,) = [m for m in local.mounts if m.target == gui.PASSWORD_MOUNT]
    assert (secret.source, secret.read_only) == (str(ROOT / ".robocore" / "desktop" / "vnc-password"), True)
    # on a robot: the copy sync ships in the live release
    remote = spec_of(p, "pidesk")
    (secret,) = [m for m in remote.mounts if m.target == gui.PASSWORD_MOUNT]
    assert (secret.source, secret.read_only) == ("/home/pi/robocore/pidesk/current/desktop/vnc-password", True)
    # desktop.open: true -> today's open desktop: no password, no mount
    opened = spec_of(project([desktop(desktop={"open": True})]), "vnc")
    assert "ROBOCORE_DESKTOP_PASSWORD_FILE" not in opened.env
    assert not [m for m in opened.mounts if m.target == gui.PASSWORD_MOUNT]
    # the script asks for VNC authentication with a password file, and serves no security only without one
    script = gui.desktop_script()
    assert "-SecurityTypes VncAuth -PasswordFile" in script and "vncpasswd -f" in script


def test_the_password_is_made_once_private_and_never_in_argv_env_or_compose(tmp_path: Path) -> None:
    import stat

    from robocore.commands.desktop_password import desktop_password
    from robocore.commands.support.displays import ensure_desktop_password

    p = project([desktop(), {"name": "viz", "runs_on": "dev", "gui": "vnc"}], root=tmp_path)
    old = os.umask(0o022)
    try:
        path = ensure_desktop_password(p)
    finally:
        os.umask(old)
    assert path == tmp_path / ".robocore" / "desktop" / "vnc-password"
    assert stat.S_IMODE(path.stat().st_mode) == 0o600 and stat.S_IMODE(path.parent.stat().st_mode) == 0o700
    password = desktop_password(p)
    assert len(password) == 8 and password.isalnum() and path.read_text() == password
    assert ensure_desktop_password(p) == path and desktop_password(p) == password  # made once, kept
    path.chmod(0o644)
    ensure_desktop_password(p)
    assert stat.S_IMODE(path.stat().st_mode) == 0o600 and path.read_text() == password  # narrowed, same value
    specs = [spec_of(p, "vnc"), spec_of(p, "viz")]
    document = yaml.safe_dump(compose_document(specs))
    assert password not in document
    for spec in specs:
        assert password not in " ".join(spec.command or ()) and password not in str(spec.env)
    # a project whose desktops are all open has no password to show
    with pytest.raises(UsageError, match="no desktop of this project asks for a password"):
        desktop_password(project([desktop(desktop={"open": True})], root=tmp_path / "other"))
    assert ensure_desktop_password(project([desktop(desktop={"open": True})], root=tmp_path / "other")) is None
    assert not (tmp_path / "other").exists()


def test_the_password_is_never_written_through_a_link(tmp_path: Path) -> None:
    from robocore.commands.support.displays import ensure_desktop_password
    from robocore.errors import UnsafePath

    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "vnc-password").write_text("theirs")
    root = tmp_path / "proj"
    (root / ".robocore").mkdir(parents=True)
    (root / ".robocore" / "desktop").symlink_to(outside)  # as a cloned repository can carry it
    with pytest.raises(UnsafePath, match="desktop"):
        ensure_desktop_password(project([desktop()], root=root))
    assert (outside / "vnc-password").read_text() == "theirs" and os.listdir(outside) == ["vnc-password"]
    (root / ".robocore" / "desktop").unlink()
    (root / ".robocore" / "desktop").mkdir()
    (root / ".robocore" / "desktop" / "vnc-password").symlink_to(outside / "vnc-password")
    with pytest.raises(UnsafePath, match="vnc-password"):
        ensure_desktop_password(project([desktop()], root=root))
    assert (outside / "vnc-password").read_text() == "theirs"


def test_a_gui_component_draws_into_the_desktop_through_its_volume_and_cookie() -> None:
    p = project([{"name": "viz", "runs_on": "dev", "gui": "vnc", "entrypoint": "rviz2"}, desktop()])
    spec = spec_of(p, "viz")
    assert spec.env["DISPLAY"] == ":1"
    assert spec.env["XAUTHORITY"] == "/tmp/.X11-unix/xauth"
    (volume,) = [m for m in spec.mounts if m.target == "/tmp/.X11-unix"]
    assert (volume.source, volume.read_only) == ("myrobot-vnc-x11", True)
    assert spec.depends_on[-1] == "vnc"  # compose starts the desktop first
    assert spec.command == ("rviz2",)
    # the compose file declares the named volume once, under the name `run` creates
    document = compose_document([spec_of(p, "vnc"), spec])
    assert document["volumes"]["myrobot-vnc-x11"] == {"name": "myrobot-vnc-x11"}
    assert "myrobot-vnc-x11:/tmp/.X11-unix:ro" in document["services"]["viz"]["volumes"]


def test_gui_true_uses_the_hosts_display_with_a_cookie_folder_of_its_own() -> None:
    p = project([{"name": "viz", "runs_on": "dev", "gui": True}, {"name": "cam", "runs_on": "pi", "gui": True,
                                                                   "environment": {"DISPLAY": ":1"}}])
    local = spec_of(p, "viz")
    assert local.env["DISPLAY"] == ":0" and local.env["XAUTHORITY"] == "/robocore/x11/xauth"
    binds = {m.target: m for m in local.mounts}
    assert binds["/tmp/.X11-unix"].source == "/tmp/.X11-unix" and binds["/tmp/.X11-unix"].read_only
    assert binds["/robocore/x11"].source == str(ROOT / ".robocore" / "x11" / "myrobot-viz")
    assert binds["/robocore/x11"].read_only
    remote = spec_of(p, "cam")
    assert remote.env["DISPLAY"] == ":1"  # the component's own DISPLAY on its host
    assert {m.target: m.source for m in remote.mounts}["/robocore/x11"] == "/home/pi/robocore/cam/.robocore-x11"
    assert gui.host_display_components(p, "pi") == [p.robot.component("cam")]


def test_a_component_without_gui_gets_no_display() -> None:
    spec = spec_of(project([{"name": "talker", "runs_on": "dev"}]), "talker")
    assert "DISPLAY" not in spec.env and "XAUTHORITY" not in spec.env
    assert not [m for m in spec.mounts if "X11" in m.target or "x11" in m.target]


# ------------------------------------------------------------------ bridge containers reach the discovery server


@pytest.mark.parametrize(("value", "network", "expected"), [
    ("127.0.0.1", "bridge", "host.docker.internal"),
    ("127.0.0.1", "host", "127.0.0.1"),
    ("192.168.1.10", "bridge", "192.168.1.10"),
    ("localhost", "bridge", "host.docker.internal"),
    ("::1", "bridge", "host.docker.internal"),
    ("fe80::1", "bridge", "fe80::1"),
])
def test_reachable_from_container(value: str, network: str, expected: str) -> None:
    assert addresses.reachable_from_container(value, network) == expected


def test_a_bridge_component_on_a_loopback_host_reaches_the_server_through_the_gateway() -> None:
    web = {"name": "web", "runs_on": "dev", "ports": ["8080:8080"], "entrypoint": "serve"}
    p = project([web, {"name": "talker", "runs_on": "dev"}], dev_ip="127.0.0.1")
    bridge = spec_of(p, "web")
    assert bridge.network_mode == "bridge"
    assert bridge.env["ROS_DISCOVERY_SERVER"] == "host.docker.internal:11811"
    assert bridge.extra_hosts == (("host.docker.internal", "host-gateway"),)
    assert bridge.docker_kwargs()["extra_hosts"] == {"host.docker.internal": "host-gateway"}
    assert bridge.compose_service()["extra_hosts"] == ["host.docker.internal:host-gateway"]
    # negative control: a host-networked neighbour keeps the loopback address, which is its host's own
    host_net = spec_of(p, "talker")
    assert host_net.env["ROS_DISCOVERY_SERVER"] == "127.0.0.1:11811"
    assert host_net.extra_hosts == () and "extra_hosts" not in host_net.docker_kwargs()
    assert "extra_hosts" not in host_net.compose_service()
    # a LAN address is reachable from the bridge as it is
    lan = spec_of(project([web]), "web")
    assert lan.env["ROS_DISCOVERY_SERVER"] == "192.168.1.10:11811"


# ------------------------------------------------------------------ the host cookie script (run here, with xauth)

COOKIE = "0123456789abcdef0123456789abcdef"


def _xauthority(path: Path, display: str) -> None:
    subprocess.run(["xauth", "-q", "-f", str(path), "add", display, "MIT-MAGIC-COOKIE-1", COOKIE], check=True,
                   capture_output=True)


def _cookie_script(display: str, folder: Path, env: dict[str, str]) -> str:
    proc = subprocess.run(gui.host_cookie_argv(display, str(folder)), capture_output=True, text=True, env=env,
                          check=True)
    return proc.stdout.strip()


@pytest.mark.skipif(shutil.which("xauth") is None, reason="needs xauth (Debian: apt-get install xauth)")
def test_the_cookie_script_copies_the_users_cookie_with_the_wildcard_family(tmp_path: Path) -> None:
    home = tmp_path / "home"
    home.mkdir()
    _xauthority(home / ".Xauthority", ":7")
    env = {"PATH": os.environ["PATH"], "HOME": str(home)}
    folder = tmp_path / "x11"
    assert _cookie_script(":7", folder, env) == f"cookie {home}/.Xauthority"
    listed = subprocess.run(["xauth", "-f", str(folder / "xauth"), "nlist"], capture_output=True, text=True,
                            check=True).stdout.split()
    assert listed[0] == "ffff" and listed[-1] == COOKIE  # any host name matches; the same secret
    assert (folder / "xauth").stat().st_mode & 0o777 == 0o600
    assert [p.name for p in folder.iterdir()] == ["xauth"]  # no temporary file left
    # negative controls: another display has no cookie; XAUTHORITY is looked at first
    other = tmp_path / "other"
    assert _cookie_script(":8", other, env) == "no-cookie"
    assert other.is_dir() and not (other / "xauth").exists()  # the folder exists for the mount
    _xauthority(tmp_path / "session", ":8")
    assert _cookie_script(":8", other, {**env, "XAUTHORITY": str(tmp_path / "session")}) == \
        f"cookie {tmp_path}/session"


def test_the_cookie_script_says_when_xauth_is_missing(tmp_path: Path) -> None:
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for tool in ("mkdir", "chmod", "id", "mktemp", "sed", "mv", "rm"):
        found = shutil.which(tool)
        assert found
        (bin_dir / tool).symlink_to(found)
    env = {"PATH": str(bin_dir), "HOME": str(tmp_path)}
    proc = subprocess.run(["/bin/sh", *gui.host_cookie_argv(":0", str(tmp_path / "x11"))[1:]], capture_output=True,
                          text=True, env=env, check=True)
    assert proc.stdout.strip() == "no-xauth"
    assert (tmp_path / "x11").is_dir()


@pytest.mark.skipif(shutil.which("xauth") is None, reason="needs xauth (Debian: apt-get install xauth)")
def test_run_copies_the_cookie_of_each_local_gui_component(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    home = tmp_path / "home"
    home.mkdir()
    _xauthority(home / ".Xauthority", ":0")
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.delenv("XAUTHORITY", raising=False)
    p = project([{"name": "viz", "runs_on": "dev", "gui": True}, {"name": "cam", "runs_on": "dev", "gui": True,
                                                                   "environment": {"DISPLAY": ":5"}},
                 {"name": "plain", "runs_on": "dev"}], root=tmp_path / "proj")
    dev = p.robot.host("dev")
    assert prepare_host_displays(p, dev, dry_run=True) == []
    assert not (tmp_path / "proj").exists()  # a dry run writes nothing
    notes = prepare_host_displays(p, dev, dry_run=False)
    assert (tmp_path / "proj/.robocore/x11/proj-viz/xauth").is_file()
    assert notes == ["cam: no X cookie of your user for display :5 (nobody logged in to it?): its windows are "
                     "refused until a run after a login"]
    assert (tmp_path / "proj/.robocore/x11/proj-cam").is_dir()  # mounted even without a cookie
    assert not (tmp_path / "proj/.robocore/x11/proj-plain").exists()


# ------------------------------------------------------------------ the desktop script


def test_the_desktop_script_is_valid_bash_and_takes_every_value_from_the_environment() -> None:
    script = gui.desktop_script()
    subprocess.run(["bash", "-n", "-c", script], check=True)
    spec_env = spec_of(project([desktop()]), "vnc").env
    used = {word for word in spec_env if word.startswith("ROBOCORE_DESKTOP_")}
    for name in used:
        assert f"${name}" in script or f"${{{name}" in script, name
    assert {"ROBOCORE_DESKTOP_DISPLAY", "ROBOCORE_DESKTOP_SIZE", "ROBOCORE_DESKTOP_VNC_PORT",
            "ROBOCORE_DESKTOP_WEB_PORT", "ROBOCORE_DESKTOP_LISTEN", "ROBOCORE_DESKTOP_XAUTHORITY"} <= used
    assert "-nolisten tcp" in script and "-interface 127.0.0.1" in script


def test_compose_file_of_a_gui_robot_is_plain_yaml() -> None:
    p = project([desktop(), {"name": "viz", "runs_on": "dev", "gui": "vnc"}])
    text = yaml.safe_dump(compose_document([spec_of(p, "vnc"), spec_of(p, "viz")]))
    assert yaml.safe_load(text)["services"]["vnc"]["command"][0] == "bash"


def test_sync_ships_the_password_folder_to_a_robots_desktop_with_its_modes(tmp_path: Path) -> None:
    from robocore.commands import sync as sync_command
    from robocore.commands.support.composefiles import write_compose_files
    from robocore.errors import UsageError as Usage

    p = project([desktop(name="pidesk", runs_on="pi")], root=tmp_path)
    with pytest.raises(Usage, match="no VNC password at"):  # before stage: said, not shipped as nothing
        (p.dds_dir).mkdir(parents=True)
        p.compose_dir.mkdir(parents=True)
        p.compose_file("pi").write_text("services: {}\n")
        sync_command.plan_host(p, p.robot.host("pi"))
    write_compose_files(p)
    (item,) = sync_command.plan_host(p, p.robot.host("pi"))
    sources = {source.name: source.path for source in item.sources}
    assert sources[gui.PASSWORD_FOLDER] == tmp_path / ".robocore" / "desktop"
    # rsync -a keeps modes: what arrives is what is here
    assert oct(sources["desktop"].stat().st_mode & 0o777) == "0o700"
    assert oct((sources["desktop"] / "vnc-password").stat().st_mode & 0o777) == "0o600"
    # an open desktop has no password to ship
    opened = project([desktop(name="pidesk", runs_on="pi", desktop={"open": True})], root=tmp_path / "o")
    write_compose_files(opened)
    (item,) = sync_command.plan_host(opened, opened.robot.host("pi"))
    assert gui.PASSWORD_FOLDER not in {source.name for source in item.sources}
