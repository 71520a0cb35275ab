"""Dockerfiles and build contexts of the base image and of each component's staged image (pure).

Three base kinds:

- ``official``: ``FROM ros:<distro>-ros-base`` (or ``base.image``), which has apt, rosdep and (ROS 2)
  colcon; ROS 1 images get colcon from their ROS apt repository;
- ``wheels``: a Debian 12 root image plus ROS 2 from PyPI wheels pinned per distro in a venv at
  ``/opt/ros/<distro>/venv``, colcon from PyPI, a generated ``/opt/ros/<distro>/setup.bash`` and a
  small ``ros2`` command;
- ``debian``: the same Debian 12 root image plus Debian's own ROS 1 packages (under ``/usr``), colcon
  from PyPI in a venv that sees them, and a generated ``/opt/ros/<distro>/setup.bash``. No rosdep
  (its database cannot be reached): dependencies are Debian package names in ``apt_packages``.

All get :data:`naming.ENTRYPOINT` (sources ROS, the image's underlays and the mounted install
tree, then execs) as ENTRYPOINT with CMD ``bash``. Common packages are colcon-built into
``/opt/robocore/common`` (base), a component's repositories into ``/opt/robocore/deps``.
Component images never contain user code: only package.xml files are copied, for rosdep.
"""

from __future__ import annotations

import json
import re
import shlex
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import TYPE_CHECKING

from robocore.config.loader import ROBOT_FILE, located
from robocore.config.model import Arch, BaseKind, Component, Repository, Robot
from robocore.errors import ConfigError, Problem
from robocore.plan import arches, cmake_packages, colcon, naming, wheels_venv
from robocore.ui import without_sgr

if TYPE_CHECKING:
    from robocore.project import Project

#: ROS 2 wheels from PyPI, pinned per distro (x86_64, CPython 3.11/3.12): the wheels base.
WHEELS: dict[str, tuple[str, ...]] = {
    "jazzy": ("ros-rclpy==7.1.6", "ros-std-msgs==5.3.6", "ros-rmw-fastrtps-cpp==8.4.3"),
    "kilted": ("ros-rclpy==9.1.2", "ros-std-msgs==5.5.1", "ros-rmw-fastrtps-cpp==9.3.3"),
}
#: colcon for ament_python packages, pytest for their tests (``robocore test``), and psutil for
#: ``fastdds discovery``. colcon-core requires pytest today; it is named because ``test`` needs it.
WHEELS_TOOLS: tuple[str, ...] = (
    "colcon-core", "colcon-ros", "colcon-python-setup-py", "colcon-library-path", "colcon-bash",
    "colcon-package-selection", "colcon-parallel-executor", "colcon-output", "pytest", "psutil",
)
#: Debian packages the official base adds to ``ros:<distro>-ros-base`` (pytest: ``robocore test``).
OFFICIAL_APT: tuple[str, ...] = ("procps", "python3-pip", "python3-pytest")
#: The folder of the wheels and debian bases' build context copied onto ``/`` (their files at their paths in the
#: image, in one build step).
BASE_TREE = "tree"
#: The installer of the wheels base's venv (pinned: its resolver and bytecode are part of the recipe).
WHEELS_INSTALLER = wheels_venv.WHEELS_INSTALLER
#: Debian packages the wheels base needs from its root image (installed only if missing).
WHEELS_APT: tuple[str, ...] = ("python3", "python3-venv", "procps", "ca-certificates")
#: Debian 12's own ROS 1 (1.15, the noetic generation) for the debian base: the core with roscpp, rospy,
#: catkin and message generation, the command-line tools, a C++ tool chain with ccache and Ninja, gtest
#: (catkin skips gtests without it) and pytest.
DEBIAN_APT: tuple[str, ...] = (
    "ros-core-dev", "rosbash", "python3-rospy", "python3-roslaunch", "python3-rosnode", "python3-rostopic",
    "python3-rosservice", "python3-rosmsg", "g++", "cmake", "make", "ninja-build", "ccache", "libgtest-dev",
    "python3-venv", "python3-pip", "python3-pytest", "procps", "ca-certificates",
)
#: The CMake generator of new build trees in the debian base (``CMAKE_GENERATOR``; a tree keeps the generator
#: it was made with). Ninja's incremental build is one process that stats the tree; Make's is a recursion of
#: makes and ``cmake -E`` helpers, each a process start, which qemu makes slow
#: (docs/design-notes.md, "arm64 under emulation").
DEBIAN_CMAKE_GENERATOR = "Ninja"
#: colcon from PyPI for the debian base (Debian has no colcon), in a venv that sees Debian's ROS modules.
DEBIAN_TOOLS: tuple[str, ...] = (
    "colcon-core", "colcon-ros", "colcon-cmake", "colcon-python-setup-py", "colcon-library-path", "colcon-bash",
    "colcon-package-selection", "colcon-parallel-executor", "colcon-output",
)
#: Debian packages the official base adds to ``ros:<distro>-ros-base`` of a ROS 1 distro (colcon: the
#: ROS apt repository of those images has it).
OFFICIAL_ROS1_APT: tuple[str, ...] = (*OFFICIAL_APT, "python3-colcon-common-extensions")

CA_IN_IMAGE = "/etc/robocore/host-ca.pem"
#: The shell of every base's RUN steps (and of the images built from it).
SHELL = ("/bin/bash", "-o", "pipefail", "-c")
CA_ENV = ("PIP_CERT", "REQUESTS_CA_BUNDLE", "SSL_CERT_FILE", "GIT_SSL_CAINFO", "CURL_CA_BUNDLE")
COMMON_PREFIX = "/opt/robocore/common"
DEPS_PREFIX = "/opt/robocore/deps"
STAGING = "/tmp/robocore"
GENERATED = "generated by robocore; do not edit"


@dataclass(frozen=True)
class ContextEntry:
    """One item of a build context: literal ``data``, or a host file/folder ``source`` (copied recursively)."""

    dest: str
    data: bytes | None = None
    source: Path | None = None
    executable: bool = False


@dataclass(frozen=True)
class ImagePlan:
    """Everything needed to build one image, and to decide whether it must be built."""

    role: str  # "base" | "component"
    name: str
    tag: str
    arch: str
    dockerfile: str
    parent: str  # the FROM reference
    context: tuple[ContextEntry, ...] = ()
    component: str | None = None
    #: labels the build sets beside robocore's own (they are not in the Dockerfile; the inputs hash has them)
    labels: Mapping[str, str] = field(default_factory=dict)

    @property
    def ref(self) -> str:
        """``name:tag``."""
        return f"{self.name}:{self.tag}"

    @property
    def platform(self) -> str:
        """The Docker platform (``linux/<arch>``)."""
        return arches.platform(self.arch)


def venv(distro: str) -> str:
    """The venv of the wheels base."""
    return f"/opt/ros/{distro}/venv"


def wheels_problems(robot: Robot) -> list[tuple[tuple[str | int, ...], str]]:
    """Why the wheels base cannot serve this robot (key path, message); empty when it can."""
    if robot.base.kind is not BaseKind.wheels:
        return []
    found: list[tuple[tuple[str | int, ...], str]] = []
    distro = robot.ros_distro.value
    if distro not in WHEELS:
        known = ", ".join(sorted(WHEELS))
        found.append((("ros_distro",), f"{distro} has no ROS 2 wheels on PyPI (wheels base: {known}); "
                                       "use base.kind: official"))
    built = {c.runs_on for c in robot.components if c.image is None}
    servers = {s.host for s in robot.discovery_servers}  # a Fast DDS server runs its host's arch's base
    for index, host in enumerate(robot.hosts):
        if host.arch is Arch.amd64 or host.name not in built | servers:
            continue
        runs = " and ".join(what for what, names in (("components built from source", built),
                                                      ("a Fast DDS discovery server", servers)) if host.name in names)
        found.append((("hosts", index, "arch"), f"{host.arch.value}: this host runs {runs} on the base of its arch, "
                                                "and ROS 2 wheels exist for amd64 only; use base.kind: official "
                                                "for this robot"))
    return found


def refuse_robot_shape(project: Project) -> None:
    """ConfigError, one line per problem with its line in robot.yaml, when the project's robot asks for images robocore
    cannot make for its shape (the wheels base's limits). ``validate``, ``prepare-base`` and ``stage`` call it
    first: the one place these checks are made."""
    found = wheels_problems(project.robot)
    if found:
        raise located(project.robot_file, found)


def _env_lines(pairs: Sequence[tuple[str, str]]) -> str:
    body = " \\\n    ".join(f"{key}={value}" for key, value in pairs)
    return f"ENV {body}"


def _ca_lines(has_ca: bool) -> list[str]:
    if not has_ca:
        return []
    return [
        "# The dev machine's trust store (public CAs plus any proxy CA), for pip/git/rosdep in builds.",
        f"COPY host-ca.pem {CA_IN_IMAGE}",
        _env_lines([(name, CA_IN_IMAGE) for name in CA_ENV]),
    ]


def _apt_install(packages: Sequence[str]) -> str:
    names = " ".join(packages)
    return ("apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "
            f"{names} && rm -rf /var/lib/apt/lists/*")


def shell_words(values: Sequence[str], key: str) -> str:
    """robot.yaml's ``values`` as shell words of a Dockerfile ``RUN`` line, each quoted on its own.

    Quoting keeps them from the shell; a control character (a newline would end the instruction and
    start another one) is refused with a ConfigError naming ``key`` (``components[0].apt_packages``).
    """
    for index, value in enumerate(values):
        if any(ord(ch) < 0x20 or ord(ch) == 0x7F for ch in value):
            raise ConfigError([Problem(ROBOT_FILE, None, f"{key}[{index}]",
                                       f"{value!r} contains a control character")])
    return " ".join(shlex.quote(value) for value in values)


def _component_apt(component: Component, key: str) -> str:
    """apt-get install of a component's packages: ``--`` before them, so none is read as an option."""
    return ("RUN apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends -- "
            f"{shell_words(component.apt_packages, key)} && rm -rf /var/lib/apt/lists/*")


def _component_pip(component: Component, key: str) -> str:
    """pip install of a component's requirements: ``--`` before them (pip's option parser stops there)."""
    return f"RUN python3 -m pip install -- {shell_words(component.pip_packages, key)}"


def _colcon_underlay(source: str, install: str) -> str:
    argv = colcon.underlay_build_argv(source, install, f"{STAGING}/colcon-build")
    return f"RUN {naming.ENTRYPOINT} {shlex.join(argv)} && rm -rf {STAGING}"


def _rosdep(paths: Sequence[str]) -> str:
    """rosdep install of the package.xml files under ``paths``. Without ``-r``: with it, a key rosdep cannot resolve
    (a typo, a key its database lacks) is reported and then ignored, rosdep exits 0 and the image silently lacks the
    dependency; without it the build stops, and :func:`rosdep_unresolved` finds rosdep's lines naming the keys."""
    froms = " ".join(f"--from-paths {p}" for p in paths)
    return (f"RUN apt-get update && {naming.ENTRYPOINT} rosdep install --rosdistro \"$ROS_DISTRO\" --ignore-src -y "
            f"{froms} && rm -rf /var/lib/apt/lists/*")


#: rosdep's lines for a key it cannot resolve: ``<package>: Cannot locate rosdep definition for [<key>]``, or
#: ``<package>: No definition of [<key>] for OS ...`` (a key its database has, but not for this OS).
_ROSDEP_UNRESOLVED = re.compile(r"^(?P<package>[^\s:]+): (?:Cannot locate rosdep definition for|No definition of) "
                                r"\[(?P<key>[^\]]+)\](?P<rest>.*)$")


def rosdep_unresolved(lines: Sequence[str]) -> list[str]:
    """What rosdep could not resolve in a build's output (the lines of the rosdep step :func:`_rosdep` writes), one
    phrase per key: ``package demo_x: no rosdep definition of 'foo'``; empty when rosdep reported none."""
    found: list[str] = []
    for line in lines:
        match = _ROSDEP_UNRESOLVED.match(without_sgr(line).strip())
        if match:
            where = match["rest"].strip()
            found.append(f"package {match['package']}: no rosdep definition of {match['key']!r}"
                         + (f" {where}" if where else ""))
    return list(dict.fromkeys(found))


def _debian_lines(distro: str, has_ca: bool) -> list[str]:
    """The debian base: Debian's ROS 1 packages, colcon in a venv that sees them, a generated setup.bash. As in
    the wheels base (:func:`_wheels_lines`), every file comes in one COPY and every setting in one ENV, and all
    the work is one RUN: each build step's commit costs seconds on this ~800 MB root (fuse-overlayfs: 6-7 s per
    step here, metadata steps too), on each arch."""
    env = venv(distro)
    # nodes run Debian's python3: a component's pip_packages go there, beside Debian's ROS modules
    settings = [("ROS_DISTRO", distro), ("LANG", "C.UTF-8"), ("PIP_DISABLE_PIP_VERSION_CHECK", "1"),
                ("PIP_NO_CACHE_DIR", "1"), ("PIP_BREAK_SYSTEM_PACKAGES", "1"),
                ("CMAKE_GENERATOR", DEBIAN_CMAKE_GENERATOR)]
    return [
        *_tree_lines("the entrypoint, setup.bash", has_ca, settings),
        *_entrypoint_lines(),
        # the root robocore bootstraps has them already (mmdebstrap --include): apt runs only for another root
        f"RUN (dpkg -s {' '.join(DEBIAN_APT)} >/dev/null 2>&1 || ({_apt_install(DEBIAN_APT)})) \\\n"
        # no pip of its own (ensurepip installs and compiles pip and setuptools, slow under qemu): the venv sees
        # Debian's pip, which installs into the venv it runs in
        f" && python3 -m venv --without-pip --system-site-packages {env}"
        f" && {env}/bin/python -m pip install {' '.join(DEBIAN_TOOLS)} \\\n"
        f" && ln -sf {env}/bin/colcon /usr/local/bin/colcon && ln -sfn {distro} /opt/ros/Debian",
    ]


def base_labels(robot: Robot) -> dict[str, str]:
    """Labels of the base image that its Dockerfile does not write: they join the one LABEL step the build appends
    (each step of its own costs seconds on fuse-overlayfs). The debian base has the C++ tool chain, so ``build``
    turns ccache on for its images."""
    if robot.base.kind is BaseKind.debian:
        return {cmake_packages.LABEL_TOOLCHAIN: cmake_packages.TOOLCHAIN_CMAKE}
    return {}


def base_dockerfile(robot: Robot, *, root_image: str, has_ca: bool, common: Sequence[str],
                    cmake: Sequence[str] = (), venv_in_root: bool = False) -> str:
    """The base image's Dockerfile. ``common``: names of common packages in the context's ``common/``;
    ``cmake``: those of them colcon builds with CMake (the wheels base then gets the CMake tool chain);
    ``venv_in_root``: the wheels base's root already has its venv (a root robocore bootstrapped with
    :func:`wheels_pins`, :mod:`robocore.plan.wheels_venv`), so the base has no venv step."""
    distro = robot.ros_distro.value
    wheels = robot.base.kind is BaseKind.wheels
    lines = [f"# robocore base image, {robot.generation} {distro} ({robot.base.kind.value}): {GENERATED}"]
    lines.append(f"FROM {root_image}")
    if not (wheels and venv_in_root):  # that root's image config has the shell
        lines.append(f"SHELL {json.dumps(list(SHELL))}")
    debian = robot.base.kind is BaseKind.debian
    if wheels:
        lines += _wheels_lines(distro, has_ca, venv_in_root=venv_in_root)
    elif debian:
        lines += _debian_lines(distro, has_ca)
    else:
        lines += _ca_lines(has_ca)
        lines.append(_env_lines([("ROS_DISTRO", distro), ("PIP_DISABLE_PIP_VERSION_CHECK", "1"),
                                 ("PIP_NO_CACHE_DIR", "1"), ("PIP_BREAK_SYSTEM_PACKAGES", "1")]))
        apt = OFFICIAL_ROS1_APT if robot.ros_version == 1 else OFFICIAL_APT
        lines.append(f"RUN {_apt_install(apt)} && rosdep update --rosdistro \"$ROS_DISTRO\"")
        lines.append(f"COPY entrypoint.sh setup-python {PurePosixPath(naming.ENTRYPOINT).parent}/")
    if wheels and cmake:
        lines += cmake_packages.toolchain_lines(distro, venv(distro), cmake)
    if common:
        lines.append(f"COPY common {STAGING}/common")
        if robot.base.kind is BaseKind.official:  # the others have no rosdep database
            lines.append(_rosdep([f"{STAGING}/common"]))
        lines.append(_colcon_underlay(f"{STAGING}/common", COMMON_PREFIX))
    if not wheels and not debian:
        lines += _entrypoint_lines()
    return "\n".join(lines) + "\n"


def _entrypoint_lines() -> list[str]:
    return [f'ENTRYPOINT ["{naming.ENTRYPOINT}"]', 'CMD ["bash"]']


#: The base kinds whose build context holds robocore's files under :data:`BASE_TREE`, copied in one step.
TREE_KINDS = frozenset({BaseKind.wheels, BaseKind.debian})


def _tree_lines(files: str, has_ca: bool, settings: list[tuple[str, str]] | None) -> list[str]:
    """The head of a base of :data:`TREE_KINDS`: robocore's ``files`` (and with ``has_ca`` the dev machine's trust
    store) in one COPY of the tree, then every setting (the trust store's first) in one ENV (None: the root's
    image config has them)."""
    trust = [(name, CA_IN_IMAGE) for name in CA_ENV] if has_ca else []
    lines = [
        f"# robocore's files at their paths: {files}"
        + (", the dev machine's trust store (public CAs plus any proxy CA, for pip/git in builds)" if has_ca else ""),
        f"COPY {BASE_TREE}/ /",
    ]
    return lines if settings is None else [*lines, _env_lines([*trust, *settings])]


def base_tree_dest(name: str, distro: str) -> str:
    """Where the wheels and debian bases' build context holds its file ``name`` (``entrypoint.sh``,
    ``setup-python``, ``*-setup.bash``, ``ros2``, ``host-ca.pem``): under :data:`BASE_TREE` at its path in the
    image, so one COPY places them all."""
    paths = {"entrypoint.sh": naming.ENTRYPOINT, "setup-python": naming.SETUP_PYTHON,
             "wheels-setup.bash": f"/opt/ros/{distro}/setup.bash",
             "debian-setup.bash": f"/opt/ros/{distro}/setup.bash", "ros2": f"{venv(distro)}/bin/ros2",
             "host-ca.pem": CA_IN_IMAGE}
    return BASE_TREE + paths[name]


def wheels_pins(distro: str) -> str:
    """The requirements of the wheels base's venv for ``distro`` (space-separated): its ROS 2 wheels and tools."""
    return " ".join(WHEELS[distro] + WHEELS_TOOLS) if distro in WHEELS else "WHEELS-UNAVAILABLE"


def _wheels_settings(distro: str) -> list[tuple[str, str]]:
    env = venv(distro)
    return [("ROS_DISTRO", distro), ("LANG", "C.UTF-8"), ("PIP_DISABLE_PIP_VERSION_CHECK", "1"),
            ("PIP_NO_CACHE_DIR", "1"), ("VIRTUAL_ENV", env), ("PATH", f"{env}/bin:$PATH")]


def wheels_root_config(distro: str, has_ca: bool) -> arches.RootConfig:
    """The settings of a wheels base whose root holds its venv, carried by that root's image config: the same
    environment (``$PATH`` read as Docker's default), entrypoint, command and shell its Dockerfile would set."""
    trust = [(name, CA_IN_IMAGE) for name in CA_ENV] if has_ca else []
    env = [(name, value.replace("$PATH", arches.DEFAULT_PATH)) for name, value in [*trust, *_wheels_settings(distro)]]
    return arches.RootConfig(env=tuple(env), entrypoint=(naming.ENTRYPOINT,), cmd=("bash",), shell=SHELL)


def _wheels_lines(distro: str, has_ca: bool, *, venv_in_root: bool) -> list[str]:
    """The wheels base up to its venv. Each build step commits a layer, and a commit costs in proportion to the
    image's size on some storage drivers (fuse-overlayfs diffs the whole tree: ~6 s per step on the 400 MB base
    here, loaded), so every file comes in one COPY and every setting in one ENV before the venv's RUN, on the
    small root; after it only the label robocore adds (and the common packages or CMake tool chain when asked).
    With ``venv_in_root`` the root has the venv and the settings already (:func:`wheels_root_config`): robocore's
    files are the one step."""
    env = venv(distro)
    if venv_in_root:
        return _tree_lines("the entrypoint, setup.bash, the ros2 command", has_ca, None)
    probe = "command -v ps >/dev/null && python3 -c 'import ensurepip, venv' 2>/dev/null"
    lines = [*_tree_lines("the entrypoint, setup.bash, the ros2 command", has_ca, _wheels_settings(distro)),
             *_entrypoint_lines()]
    script = wheels_venv.install_script(env, wheels_pins(distro))
    lines.append(f"RUN ({probe} || ({_apt_install(WHEELS_APT)})) \\\n && {script}")
    return lines


def repo_folder(repo: Repository) -> str:
    """The folder of a repository under the deps source tree (``folder``, else from the URL; validate
    refuses unsafe ones)."""
    return repo.checkout_folder


def component_dockerfile(
    robot: Robot,
    component: Component,
    *,
    base_ref: str,
    package_xmls: Sequence[str] = (),
    repo_folders: Sequence[str] = (),
    cmake: Sequence[str] = (),
) -> str:
    """A component's staged image: base + apt + pip + CMake tool chain (wheels) + repositories + rosdep
    (official) + postinstall.

    ``package_xmls``: context paths (under ``rosdep/``) of the component's package.xml files, used
    only when the base has rosdep; ``repo_folders``: folders under the context's ``repos/``;
    ``cmake``: the packages of its workspace and repositories that colcon builds with CMake.
    """
    official = robot.base.kind is BaseKind.official
    lines = [f"# robocore image of component {component.name}: {GENERATED}", f"FROM {base_ref}"]
    key = f"components[{_index(robot, component)}]"
    if component.apt_packages:
        lines.append(_component_apt(component, f"{key}.apt_packages"))
    if component.pip_packages:
        lines.append(_component_pip(component, f"{key}.pip_packages"))
    if cmake and robot.base.kind is BaseKind.wheels:
        distro = robot.ros_distro.value
        lines += cmake_packages.toolchain_lines(distro, venv(distro), cmake)
    rosdep_paths: list[str] = []
    if repo_folders:
        lines.append(f"COPY repos {STAGING}/deps")
        rosdep_paths.append(f"{STAGING}/deps")
    if official and package_xmls:
        lines.append(f"COPY rosdep {STAGING}/rosdep")
        rosdep_paths.append(f"{STAGING}/rosdep")
    if official and rosdep_paths:
        lines.append(_rosdep(rosdep_paths))
    if repo_folders:
        lines.append(_colcon_underlay(f"{STAGING}/deps", DEPS_PREFIX))
    elif rosdep_paths:
        lines.append(f"RUN rm -rf {STAGING}")
    for command in component.postinstall:
        lines.append("RUN " + json.dumps([naming.ENTRYPOINT, "bash", "-c", command]))
    return "\n".join(lines) + "\n"


def _index(robot: Robot, component: Component) -> int | str:
    for index, comp in enumerate(robot.components):
        if comp is component or comp.name == component.name:
            return index
    return component.name


def rosdep_dest(package_xml: PurePosixPath) -> str:
    """Context path of a component's package.xml (relative to its workspace)."""
    return str(PurePosixPath("rosdep") / package_xml)
