"""The argv robocore hands to ssh, rsync, git, docker, apt and pip, built from hostile values.

Models are made without validation (``model_construct``, ``model_copy(update=...)``), so that only the
argv layer stands between a value and the tool: no value may land in an option position (every
operand comes after the tool's end-of-options marker, or is attached to its option as ``--opt=value``),
and each value must reach the tool as one unchanged argument. Where a tool can be run harmlessly
(sh, git, rsync with a local shim instead of ssh), it is run, with a marker file that a command
smuggled into a value would create.
"""

from __future__ import annotations

import shlex
import shutil
import subprocess
from pathlib import Path, PurePosixPath

import pytest

from robocore.adapters import ssh, vcs
from robocore.commands import connect
from robocore.config.model import Component, DockerAccess, Host, Robot, TlsFiles
from robocore.config.values import is_ipv6
from robocore.errors import BuildError, ConfigError, HostError, UsageError
from robocore.plan import devshell, dockerfiles
from robocore.plan import sync as plan
from robocore.plan.addresses import bare, bracketed
from robocore.project import Project

#: ``@M@`` becomes the path of a marker file that a command smuggled into a value would create.
HOSTILE = [
    "-oProxyCommand=touch @M@",
    "--upload-pack=touch @M@",
    "-",
    "a b",
    "x;touch @M@",
    "$(touch @M@)",
    "`touch @M@`",
    "a\nb",
    "'q\"\\",
    "fe80::1",
]
ADDRESSES = ["10.0.0.5", "fe80::1", "2001:db8::7", "[2001:db8::8]", "fe80::1%eth0", "robot.local"]


def values(marker: Path) -> list[str]:
    return [v.replace("@M@", str(marker)) for v in HOSTILE]


def host(ip: str = "10.0.0.5", user: str = "pi", **extra: object) -> Host:
    return Host.model_construct(name="h", ip=ip, user=user, ssh_port=2222, **extra)  # type: ignore[arg-type]


def after_marker(argv: list[str], marker: str = "--") -> list[str]:
    assert marker in argv, argv
    return argv[argv.index(marker) + 1:]


def before_marker(argv: list[str], marker: str = "--") -> list[str]:
    return argv[:argv.index(marker)]


# --------------------------------------------------------------------------------------------- ssh


@pytest.mark.parametrize("ip", [*ADDRESSES, "-oProxyCommand=x", "a b"])
@pytest.mark.parametrize("user", ["pi", "-l", "a;b"])
def test_ssh_destination_is_the_only_operand_after_the_end_of_options(ip: str, user: str) -> None:
    argv = ssh.ssh_argv(host(ip, user), ["true"])
    assert after_marker(argv) == [f"{user}@{bare(ip)}", "true"]
    assert not any(ip in arg or user in arg for arg in before_marker(argv)[1:] if arg not in {"-p", "2222"})


def test_ssh_remote_command_is_quoted_argument_by_argument(tmp_path: Path) -> None:
    marker = tmp_path / "MARKER"
    remote = ["printf", "<%s>\\n", *values(marker)]
    argv = ssh.ssh_argv(host(), remote)
    command = argv[-1]
    assert shlex.split(command) == remote
    # the remote side runs the command string with a POSIX shell: run it here the same way
    done = subprocess.run(["sh", "-c", command], capture_output=True, text=True, check=True)
    assert done.stdout == "".join(f"<{v}>\n" for v in values(marker))
    assert not marker.exists()


def test_rsh_command_splits_back_into_robocores_options_only(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv(ssh.CONFIG_ENV, str(tmp_path / "my config; $(id)"))
    words = shlex.split(ssh.rsh_command(host("-oProxyCommand=x")))
    assert words[0] == "ssh" and words[words.index("-F") + 1] == str(tmp_path / "my config; $(id)")
    assert not any("ProxyCommand" in w for w in words)


def test_interactive_connect_over_ssh_quotes_the_docker_argv(tmp_path: Path) -> None:
    marker = tmp_path / "MARKER"
    env = {f"K{i}": v for i, v in enumerate(values(marker))}
    docker_argv = connect.docker_exec_argv("proj-talker", ["sh", "-c", "echo hi"], env, tty=True)
    assert before_marker(docker_argv)[:3] == ["docker", "exec", "-it"]
    flags = before_marker(docker_argv)[3:]
    assert all(arg.startswith("--env=") for arg in flags)
    assert {arg.removeprefix("--env=") for arg in flags} == {f"{k}={v}" for k, v in env.items()}
    assert after_marker(docker_argv) == ["proj-talker", "sh", "-c", "echo hi"]
    project = Project(root=tmp_path, robot=Robot.model_construct())
    full, extra = connect.interactive_argv(project, host("-oProxyCommand=x"), docker_argv, tty=True)
    assert extra == {}
    assert after_marker(full)[0] == "pi@-oProxyCommand=x"
    assert shlex.split(after_marker(full)[1]) == docker_argv


def test_interactive_connect_over_tls_attaches_paths_to_their_flags(tmp_path: Path) -> None:
    tls = TlsFiles.model_construct(ca_cert="-ca.pem", client_cert="--cert", client_key="/k ey;x")
    target = host("2001:db8::7", docker=DockerAccess.tls, tls=tls, docker_port=2376)
    project = Project(root=tmp_path, robot=Robot.model_construct())
    full, extra = connect.interactive_argv(project, target, ["docker", "exec", "-i", "--", "c", "sh"], tty=False)
    assert full[:5] == ["docker", "--tlsverify", f"--tlscacert={tmp_path}/-ca.pem", f"--tlscert={tmp_path}/--cert",
                        "--tlskey=/k ey;x"]
    assert extra == {"DOCKER_HOST": "tcp://[2001:db8::7]:2376"}


# --------------------------------------------------------------------------------------------- rsync


def sync_item(root: PurePosixPath, sources: tuple[plan.Source, ...] = ()) -> plan.ComponentSync:
    return plan.ComponentSync(component="talker", host="h", root=root, sources=sources, compose_name="h.yaml")


@pytest.mark.parametrize("ip", ADDRESSES)
def test_rsync_operands_follow_the_end_of_options_and_ipv6_is_bracketed(ip: str, tmp_path: Path) -> None:
    marker = tmp_path / "MARKER"
    for value in values(marker):
        root = PurePosixPath("/srv") / value
        source = plan.Source(tmp_path / value / "install", "install")
        argv = plan.rsync_argv(sync_item(root, (source,)), host(ip), "ssh -p 2222")
        assert "-s" in before_marker(argv)  # --protect-args: paths never go through the remote shell
        assert after_marker(argv) == [source.rsync_arg, f"pi@{bracketed(ip)}:{root}/staging/"]
        options = before_marker(argv)
        assert [arg for arg in options if str(root) in arg] == [f"--link-dest={root}/current/"]
        remote = after_marker(argv)[-1]
        assert remote.split("@", 1)[1].startswith(f"[{bare(ip)}]:" if is_ipv6(bare(ip)) else f"{ip}:")


@pytest.mark.parametrize("ip, user", [("-oProxyCommand=x", "pi"), ("[-x]", "pi"), ("10.0.0.5", "-lroot")])
def test_rsync_refuses_a_host_or_user_that_ssh_would_read_as_an_option(ip: str, user: str, tmp_path: Path) -> None:
    with pytest.raises(HostError, match="starts with '-'"):
        plan.rsync_argv(sync_item(PurePosixPath("/srv/x")), host(ip, user), "ssh")


@pytest.mark.skipif(shutil.which("rsync") is None, reason="rsync is not installed")
def test_rsync_delivers_into_a_hostile_path_unchanged(tmp_path: Path) -> None:
    """A real rsync through a shim instead of ssh (it runs the server side here): the hostile mount
    root is the folder the files land in, the shim never sees it (``-s``), and nothing ran."""
    marker = tmp_path / "MARKER"
    install = tmp_path / "local" / "install"
    (install / "share").mkdir(parents=True)
    (install / "share" / "file.txt").write_text("payload")
    seen = tmp_path / "shim-args"
    shim = tmp_path / "shim"
    shim.write_text(f'#!/bin/sh\nprintf "%s\\n" "$@" >> "{seen}"\n'
                    'if [ "$1" = -l ]; then shift 2; fi\nshift\nexec "$@"\n')
    shim.chmod(0o755)
    for value in [f"a b;touch {marker}", f"$(touch {marker})", "x\ny", "-rf", "fe80::1:z"]:
        root = tmp_path / "remote" / value
        argv = plan.rsync_argv(sync_item(PurePosixPath(root), (plan.Source(install, "install"),)),
                               host("fe80::1", "me"), str(shim))
        (root / "staging").mkdir(parents=True)
        done = subprocess.run(argv, capture_output=True, text=True, timeout=60)
        assert done.returncode == 0, done.stderr
        assert (root / "staging" / "install" / "share" / "file.txt").read_text() == "payload"
        assert str(root) not in seen.read_text()
    assert not marker.exists()


# --------------------------------------------------------------------------------------------- git


BAD_VERSIONS = ["-x", "--upload-pack=touch x", "a b", "a\nb", "..", "a..b", "x.lock", "a/x.lock/b",
                "@", "a@{1}", "/x", "x/", "a//b", ".x", "a/.b", "x.", "~1", "a^", "a:b", "a?", "a*", "a[", "a\\b",
                "\x1b[2J", ""]
#: Valid ref names for git (``a;b`` too): harmless, since no shell ever sees them.
GOOD_VERSIONS = ["main", "v1.2.3", "feature/x-y", "0123abcd" * 5, "release-2024", "HEAD", "a@b", "@x", "a;b", "$(id)"]


@pytest.mark.parametrize("version", BAD_VERSIONS)
def test_git_refuses_versions_that_are_not_ref_names(version: str) -> None:
    with pytest.raises(UsageError, match="not a valid branch, tag or commit name"):
        vcs.fetch_argv("https://example.com/r.git", version)


@pytest.mark.parametrize("version", GOOD_VERSIONS)
def test_git_takes_ref_names_as_operands_after_the_end_of_options(version: str) -> None:
    url = "https://example.com/a b;c.git"
    argv = vcs.fetch_argv(url, version)
    assert after_marker(argv, "--end-of-options") == [url, version]
    assert before_marker(argv, "--end-of-options") == [*vcs.git_config(), "fetch", "-q", "--depth", "1"]


def git_ok(version: str) -> bool:
    if shutil.which("git") is None:
        pytest.skip("git is not installed")
    return subprocess.run(["git", "check-ref-format", "--allow-onelevel", version], capture_output=True).returncode == 0


@pytest.mark.parametrize("version", [v for v in BAD_VERSIONS + GOOD_VERSIONS if not v.startswith("-")])
def test_the_ref_name_rules_agree_with_git_check_ref_format(version: str) -> None:
    """A negative control for the hand-written rules: git's own check gives the same answer."""
    try:
        vcs.check_version(version)
        ours = True
    except UsageError:
        ours = False
    assert ours == git_ok(version) or version == "HEAD"


@pytest.mark.parametrize("url", ["-x", "--upload-pack=touch x", "a\nb", "", "\x1b]0;t\x07"])
def test_git_refuses_urls_it_would_read_as_options(url: str) -> None:
    with pytest.raises(UsageError, match="not a repository URL"):
        vcs.fetch_argv(url, "main")


def test_git_config_allows_network_transports_only_unless_an_entry_opts_in() -> None:
    default = vcs.git_config()
    assert all(default[i] == "-c" for i in range(0, len(default), 2))
    settings = dict(default[i + 1].split("=") for i in range(0, len(default), 2))
    assert default[:2] == ["-c", "protocol.allow=never"]
    assert {k: v for k, v in settings.items() if v == "always"} == {
        f"protocol.{name}.allow": "always" for name in ("https", "ssh", "http", "git")}
    assert settings["protocol.ext.allow"] == settings["protocol.file.allow"] == "never"
    for opt_in, opened in (("file", "file"), ("ext", "ext"), ("git", None), (None, None)):
        config = vcs.git_config(allow_protocol=opt_in)
        for name in ("ext", "file"):
            assert f"protocol.{name}.allow={'always' if name == opened else 'never'}" in config


def _repo(path: Path) -> None:
    path.mkdir(parents=True)
    run = lambda *a: subprocess.run(["git", *a], cwd=path, check=True, capture_output=True)  # noqa: E731
    run("init", "-q", "-b", "main")
    (path / "f").write_text("x")
    run("add", "-A")
    run("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "-m", "x")


@pytest.mark.skipif(shutil.which("git") is None, reason="git is not installed")
def test_git_refuses_local_and_ext_transports_by_default(tmp_path: Path) -> None:
    marker = tmp_path / "MARKER"
    upstream = tmp_path / "upstream"
    _repo(upstream)
    for url in (upstream.as_uri(), str(upstream)):
        with pytest.raises(BuildError, match="not allowed"):
            vcs.fetch(url, "main", tmp_path / "dest")
    assert len(vcs.fetch(upstream.as_uri(), "main", tmp_path / "dest", allow_protocol="file")) == 40  # opted in
    ext = f"ext::sh -c touch% {marker}"
    for opt_in in (None, "file", "git"):
        with pytest.raises(BuildError, match="not allowed"):
            vcs.fetch(ext, None, tmp_path / "ext", allow_protocol=opt_in)
    assert not marker.exists()
    with pytest.raises(BuildError):  # negative control: opted in, ext:: runs its command (then fails the fetch)
        vcs.fetch(ext, None, tmp_path / "ext", allow_protocol="ext")
    assert marker.exists()


@pytest.mark.skipif(shutil.which("git") is None, reason="git is not installed")
def test_git_hardening_holds_even_for_a_value_that_slipped_past_the_checks(tmp_path: Path) -> None:
    """The checks bypassed: an option-like URL after --end-of-options and an ext:: URL still run nothing;
    the same ext:: URL with the transport allowed does run (so the marker would show it)."""
    marker = tmp_path / "MARKER"
    repo = tmp_path / "r"
    subprocess.run(["git", "init", "-q", str(repo)], check=True)
    for url in (f"--upload-pack=touch {marker}", f"ext::sh -c touch% {marker}"):
        argv = ["git", *vcs.git_config(), "fetch", "-q", "--depth", "1", "--end-of-options", url, "HEAD"]
        assert subprocess.run(argv, cwd=repo, capture_output=True).returncode != 0
        assert not marker.exists(), url
    control = ["git", "-c", "protocol.ext.allow=always", "fetch", "-q", f"ext::sh -c touch% {marker}", "HEAD"]
    subprocess.run(control, cwd=repo, capture_output=True)
    assert marker.exists(), "negative control: an allowed ext:: transport runs its command"


# --------------------------------------------------------------------------------------------- docker


def test_dev_shell_exec_puts_the_container_after_the_end_of_options(tmp_path: Path) -> None:
    marker = tmp_path / "MARKER"
    session = {f"V{i}": v for i, v in enumerate(values(marker))}
    spec = devshell.ShellSpec(name="proj-arm-shell", image="img", component="arm", uid=1000, gid=1000, user="u",
                              home="/home/u", workdir="/robocore/ws", mounts=(), environment={}, session_env=session,
                              labels={})
    for cmd in (None, f"echo $(touch {marker})"):
        argv = devshell.exec_argv(spec, cmd=cmd, stdin_tty=False)
        options = before_marker(argv)
        env_values = [options[i + 1] for i, arg in enumerate(options) if arg == "-e"]
        assert env_values == [f"{k}={v}" for k, v in session.items()]  # each whole, after its -e
        assert after_marker(argv) == ["proj-arm-shell", "bash", "-l"] if cmd is None else \
            after_marker(argv) == ["proj-arm-shell", "bash", "-lc", cmd]


@pytest.mark.parametrize("ip, url", [("fe80::1", "[fe80::1]"), ("2001:db8::7", "[2001:db8::7]"),
                                     ("10.0.0.5", "10.0.0.5"), ("robot.local", "robot.local")])
def test_docker_urls_bracket_ipv6(ip: str, url: str) -> None:
    from robocore.adapters.docker_hosts import describe

    assert describe(host(ip, docker=DockerAccess.ssh)) == f"ssh://pi@{url}:2222"
    assert describe(host(ip, docker=DockerAccess.tls)) == f"https://{url}:2376 (tls)"
    assert describe(host(ip, docker=DockerAccess.tcp)) == f"tcp://{url}:2375 (insecure)"


# --------------------------------------------------------------------------------------------- apt and pip


def robot_with(apt: list[str], pip: list[str]) -> tuple[Robot, Component]:
    robot = Robot.model_validate({"ros_distro": "jazzy", "hosts": [{"name": "dev", "ip": "127.0.0.1"}],
                                  "components": [{"name": "c", "runs_on": "dev", "apt_packages": ["curl"],
                                                  "pip_packages": ["six"]}]})
    component = robot.components[0].model_copy(update={"apt_packages": apt, "pip_packages": pip})
    return robot.model_copy(update={"components": [component]}), component


#: Stand-ins for the tools of a RUN line: each prints its arguments, one per line, between < >.
FAKE_TOOLS = ('apt-get() { printf "apt-get"; printf " <%s>" "$@"; echo; }; '
              'python3() { printf "python3"; printf " <%s>" "$@"; echo; }; rm() { :; }; ')


def test_apt_and_pip_values_reach_their_tool_after_the_end_of_options(tmp_path: Path) -> None:
    marker = tmp_path / "MARKER"
    hostile = [v for v in values(marker) if "\n" not in v]
    robot, component = robot_with(hostile, hostile)
    text = dockerfiles.component_dockerfile(robot, component, base_ref="b")
    runs = [line.removeprefix("RUN ") for line in text.splitlines()
            if "apt-get install" in line or "pip install" in line]
    assert len(runs) == 2
    for run in runs:
        done = subprocess.run(["bash", "-c", FAKE_TOOLS + run], capture_output=True, text=True, check=True)
        install = [line for line in done.stdout.splitlines() if " <install> " in line]
        assert len(install) == 1
        words = install[0].split(" <--> ", 1)[1]
        assert words == " ".join(f"<{v}>" for v in hostile)
    assert not marker.exists()


@pytest.mark.parametrize("field", ["apt_packages", "pip_packages"])
@pytest.mark.parametrize("value", ["a\nRUN touch /x", "a\rb", "a\x1bb", "a\x00"])
def test_a_value_that_would_end_the_instruction_is_refused(field: str, value: str) -> None:
    robot, component = robot_with(["ok"] if field == "pip_packages" else ["ok", value],
                                  ["ok", value] if field == "pip_packages" else ["ok"])
    with pytest.raises(ConfigError) as info:
        dockerfiles.component_dockerfile(robot, component, base_ref="b")
    assert [p.path for p in info.value.problems] == [f"components[0].{field}[1]"]
    assert "control character" in info.value.problems[0].message


def test_postinstall_commands_stay_one_json_instruction() -> None:
    robot, component = robot_with([], [])
    component = component.model_copy(update={"postinstall": ["echo a\nRUN touch /x", "x\"]; RUN [\"y"]})
    text = dockerfiles.component_dockerfile(robot, component, base_ref="b")
    assert [line for line in text.splitlines() if line.startswith("RUN")] == [
        'RUN ["/robocore/entrypoint.sh", "bash", "-c", "echo a\\nRUN touch /x"]',
        'RUN ["/robocore/entrypoint.sh", "bash", "-c", "x\\"]; RUN [\\"y"]',
    ]
