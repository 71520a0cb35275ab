"""CMake packages on the wheels base: which packages need a compiler, what the image gets for them (pure).

The ROS 2 wheels from PyPI ship the ament_cmake and rosidl tool chains, so ``ament_cmake`` packages
with ``rosidl_generate_interfaces`` (custom messages and services) build on the wheels base, given
a C/C++ tool chain from Debian, the whole tool set pinned to the distro's wheels (installing only
``ament_cmake`` and ``rosidl_default_generators`` fails one missing CMake package at a time), and
two symlinks: the wheels' exported CMake targets name the wheel builder's Python include folders.
There are no ``rclcpp`` wheels: C++ *nodes* cannot be built on this base, and a package that
depends on a C++ client library is refused in one line before any image is built.

Only images whose packages need it get the tool chain: the base when a common package does, a
component's image when its workspace or its repositories do. Such an image carries the label
:data:`LABEL_TOOLCHAIN`, which ``build`` reads to turn on ccache and to refuse a workspace that
gained a CMake package since its image was staged.
"""

from __future__ import annotations

import re
import xml.parsers.expat
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

#: colcon build types that run CMake (and so need cmake, a compiler and, for ROS, the ament tool set).
CMAKE_BUILD_TYPES = frozenset({"ament_cmake", "cmake"})
#: C and C++ client libraries: no wheels of them exist, so nothing depending on them builds on the wheels base.
CPP_CLIENT_LIBRARIES = frozenset({
    "rclcpp", "rclcpp_action", "rclcpp_components", "rclcpp_lifecycle", "rclc", "rclc_lifecycle",
    "rclc_parameter",
})
#: package.xml tags naming a dependency that the build (or its tests) needs.
DEPEND_TAGS = frozenset({"depend", "build_depend", "build_export_depend", "exec_depend", "run_depend",
                         "test_depend"})

#: Debian packages of the tool chain (python3-dev: the generated Python type support is a C extension).
CMAKE_APT: tuple[str, ...] = ("cmake", "g++", "gcc", "make", "python3-dev", "ccache")

_AMENT_CMAKE = ("core", "export-definitions", "export-dependencies", "export-include-directories",
                "export-interfaces", "export-libraries", "export-link-flags", "export-targets", "gen-version-h",
                "gmock", "gtest", "include-directories", "libraries", "pytest", "python", "target-dependencies",
                "test", "vendor-package", "version")
_ROSIDL = {  # rosidl wheels of one release share a version, except these families
    "adapter": "core", "cli": "core", "cmake": "core", "generator-c": "core", "generator-cpp": "core",
    "generator-type-description": "core", "parser": "core", "pycommon": "core", "runtime-c": "core",
    "runtime-cpp": "core", "typesupport-interface": "core", "typesupport-introspection-c": "core",
    "typesupport-introspection-cpp": "core", "typesupport-c": "typesupport", "typesupport-cpp": "typesupport",
    "typesupport-fastrtps-c": "fastrtps", "typesupport-fastrtps-cpp": "fastrtps", "core-generators": "defaults_core",
    "core-runtime": "defaults_core", "default-generators": "defaults", "default-runtime": "defaults",
    "dynamic-typesupport": "dynamic", "dynamic-typesupport-fastrtps": "dynamic_fastrtps", "generator-py": "py",
}


def _pins(versions: Mapping[str, str], others: Mapping[str, str]) -> tuple[str, ...]:
    ament = [f"ros-ament-cmake=={versions['ament_cmake']}"]
    ament += [f"ros-ament-cmake-{name}=={versions['ament_cmake']}" for name in _AMENT_CMAKE]
    rosidl = [f"ros-rosidl-{name}=={versions[family]}" for name, family in sorted(_ROSIDL.items())]
    return (*ament, *rosidl, *(f"ros-{name}=={version}" for name, version in sorted(others.items())))


#: The ament_cmake/rosidl tool set per distro, pinned to the releases of :data:`dockerfiles.WHEELS`
#: (their rclpy, std_msgs and rmw_fastrtps_cpp resolve to exactly these versions).
CMAKE_WHEELS: dict[str, tuple[str, ...]] = {
    "jazzy": _pins(
        {"ament_cmake": "2.5.4", "core": "4.6.6", "typesupport": "3.2.2", "fastrtps": "3.6.2", "defaults_core": "0.2.0",
         "defaults": "1.6.0", "dynamic": "0.1.2", "dynamic_fastrtps": "0.1.0", "py": "0.22.2"},
        {"ament-cmake-ros": "0.12.0", "ament-cmake-cppcheck": "0.17.3", "ament-cmake-cpplint": "0.17.3",
         "ament-cmake-flake8": "0.17.3", "ament-cmake-pep257": "0.17.3", "ament-cmake-uncrustify": "0.17.3",
         "ament-cppcheck": "0.17.3", "ament-cpplint": "0.17.3", "ament-flake8": "0.17.3", "ament-pep257": "0.17.3",
         "ament-uncrustify": "0.17.3", "ament-index-cpp": "1.8.1",
         "ament-package": "0.16.4", "ament-index-python": "1.8.1", "ament-lint": "0.17.3", "gmock-vendor": "1.14.9000",
         "gtest-vendor": "1.14.9000", "python-cmake-module": "0.11.1", "fastcdr": "2.2.5", "fastrtps": "2.14.5",
         "fastrtps-cmake-module": "3.6.2", "rcutils": "6.7.4", "rcpputils": "2.11.2", "rpyutils": "0.4.2",
         "builtin-interfaces": "2.0.3", "service-msgs": "2.0.3", "action-msgs": "2.0.3",
         "unique-identifier-msgs": "2.5.0", "type-description-interfaces": "2.0.3"},
    ),
    "kilted": _pins(
        {"ament_cmake": "2.7.3", "core": "4.9.5", "typesupport": "3.3.3", "fastrtps": "3.8.1", "defaults_core": "0.3.1",
         "defaults": "1.7.1", "dynamic": "0.3.1", "dynamic_fastrtps": "0.4.1", "py": "0.24.2"},
        {"ament-cmake-ros": "0.14.5", "ament-cmake-ros-core": "0.14.5", "ament-cmake-cppcheck": "0.19.2",
         "ament-cmake-cpplint": "0.19.2", "ament-cmake-flake8": "0.19.2", "ament-cmake-pep257": "0.19.2",
         "ament-cmake-uncrustify": "0.19.2", "ament-cppcheck": "0.19.2", "ament-cpplint": "0.19.2",
         "ament-flake8": "0.19.2", "ament-pep257": "0.19.2", "ament-uncrustify": "0.19.2", "ament-index-cpp": "1.11.0",
         "ament-package": "0.17.2", "ament-index-python": "1.11.0", "ament-lint": "0.19.2", "gmock-vendor": "1.15.1",
         "gtest-vendor": "1.15.1", "fastcdr": "2.3.3", "fastdds": "3.2.3", "rcutils": "6.9.8", "rcpputils": "2.13.5",
         "rpyutils": "0.6.3", "builtin-interfaces": "2.3.0", "service-msgs": "2.3.0", "action-msgs": "2.3.0",
         "unique-identifier-msgs": "2.7.0", "type-description-interfaces": "2.3.0"},
    ),
}

_NAME_RE = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_\-]*")

LABEL_TOOLCHAIN = "dev.robocore.toolchain"
TOOLCHAIN_CMAKE = "cmake"
#: The wheel builder's CPython prefix, which the wheels' exported CMake targets name.
WHEEL_BUILDER_PYTHON = "/opt/python"


@dataclass(frozen=True)
class Manifest:
    """What robocore needs from one package.xml: the package, how colcon builds it, and where it
    depends on a C++ client library (tag, dependency and line), if it does."""

    path: str  # as shown in messages: project-relative path of the package.xml
    name: str
    build_type: str
    cpp_client: tuple[str, str, int] | None = None
    #: Every dependency: (tag, dependency, line, its ``condition`` attribute or ""), in file order.
    depends: tuple[tuple[str, str, int, str], ...] = ()

    @property
    def uses_cmake(self) -> bool:
        """Whether colcon runs CMake for this package."""
        return self.build_type in CMAKE_BUILD_TYPES


def read_manifest(text: str, path: str, *, has_cmakelists: bool) -> Manifest:
    """The :class:`Manifest` of a package.xml ``text``; ``has_cmakelists``: a CMakeLists.txt sits beside it.

    The build type is ``<export><build_type>``; without one, a package with a CMakeLists.txt and the
    buildtool ``ament_cmake`` is ``ament_cmake``, anything else ``catkin`` (colcon's default). A file
    that is not XML gives build type ``unknown`` (colcon reports it in its own words).
    """
    found = _Scan()
    parser = xml.parsers.expat.ParserCreate()
    parser.StartElementHandler = found.start
    parser.EndElementHandler = found.end
    parser.CharacterDataHandler = found.text
    found.parser = parser
    try:
        parser.Parse(text, True)
    except xml.parsers.expat.ExpatError:
        return Manifest(path=path, name="", build_type="unknown", cpp_client=found.cpp_client,
                        depends=tuple(found.depends))
    build_type = found.build_type
    if not build_type:  # colcon's default is catkin; an ament_cmake buildtool with a CMakeLists.txt says otherwise
        build_type = "ament_cmake" if has_cmakelists and "ament_cmake" in found.buildtools else "catkin"
    return Manifest(path=path, name=found.name, build_type=build_type, cpp_client=found.cpp_client,
                    depends=tuple(found.depends))


class _Scan:
    """expat handlers collecting name, build type, buildtools and the first C++ client dependency."""

    def __init__(self) -> None:
        self.parser: xml.parsers.expat.XMLParserType | None = None
        self.stack: list[str] = []
        self.chunks: list[str] = []
        self.line = 0
        self.name = ""
        self.build_type = ""
        self.buildtools: list[str] = []
        self.cpp_client: tuple[str, str, int] | None = None
        self.depends: list[tuple[str, str, int, str]] = []
        self.condition = ""

    def start(self, tag: str, attrs: dict[str, str]) -> None:
        self.stack.append(tag)
        self.chunks = []
        self.condition = attrs.get("condition", "")
        self.line = self.parser.CurrentLineNumber if self.parser else 0

    def text(self, data: str) -> None:
        self.chunks.append(data)

    def end(self, tag: str) -> None:
        value = "".join(self.chunks).strip()
        parent = self.stack[-2] if len(self.stack) > 1 else ""
        if tag == "name" and parent == "package":
            self.name = value
        elif tag == "build_type" and parent == "export":
            self.build_type = value
        elif tag == "buildtool_depend":
            self.buildtools.append(value)
        if tag in DEPEND_TAGS | {"buildtool_depend"} and value:
            self.depends.append((tag, value, self.line, self.condition))
        if tag in DEPEND_TAGS and value in CPP_CLIENT_LIBRARIES and self.cpp_client is None:
            self.cpp_client = (tag, value, self.line)
        self.stack.pop()
        self.chunks = []


def cmake_packages(manifests: Iterable[Manifest]) -> list[str]:
    """Names of the packages colcon builds with CMake, sorted; a name that is not a plain package name
    (it ends up in a Dockerfile comment, where a newline would start an instruction) shows as ``?``."""
    return sorted({m.name if _NAME_RE.fullmatch(m.name) else "?" for m in manifests if m.uses_cmake})


@dataclass(frozen=True)
class Refusal:
    """A package.xml line a base cannot serve (a package the wheels base cannot build, a dependency the debian
    base cannot resolve): file, line, the tag and the one-line reason."""

    file: str
    line: int | None
    key: str
    message: str


def wheels_refusals(distro: str, manifests: Sequence[Manifest]) -> list[Refusal]:
    """Why these packages cannot build on the wheels base of ``distro``; empty when they can.

    A dependency on a C++ client library is refused where it is declared; CMake packages on a
    distro without a pinned tool set are refused once, at the first of them.
    """
    found = [Refusal(m.path, line, tag, f"no {dependency} wheels: C++ nodes cannot be built on the wheels base; "
                                        "use base kind official")
             for m in manifests if m.cpp_client is not None for tag, dependency, line in [m.cpp_client]]
    cmake = [m for m in manifests if m.uses_cmake]
    if cmake and distro not in CMAKE_WHEELS:
        known = ", ".join(sorted(CMAKE_WHEELS))
        found.append(Refusal(cmake[0].path, None, "export.build_type",
                             f"{cmake[0].build_type} package {cmake[0].name or '?'}: the wheels base builds CMake "
                             f"packages for {known} only, not {distro}; use base kind official"))
    return found


def toolchain_lines(distro: str, venv: str, packages: Sequence[str]) -> list[str]:
    """Dockerfile lines that give an image what CMake packages need on the wheels base.

    Idempotent and cheap on an image that has it already (the base, when a common package needed
    it): apt runs only when a tool is missing, pip finds its pins satisfied, the links are replaced.
    """
    pins = " ".join(CMAKE_WHEELS.get(distro, ("CMAKE-WHEELS-UNAVAILABLE",)))
    shown = ", ".join(name if _NAME_RE.fullmatch(name) else "?" for name in packages)
    tools = " ".join(f"command -v {tool} >/dev/null &&" for tool in ("cmake", "g++", "gcc", "make", "ccache"))
    apt = " ".join(CMAKE_APT)
    ver = "\"$(python3 -c 'import sys; print(\"%d.%d\" % sys.version_info[:2])')\""
    tag = "\"cp${v%.*}${v#*.}-cp${v%.*}${v#*.}\""
    return [
        f"# CMake packages ({shown}): a C/C++ tool chain and the ament_cmake/rosidl wheels",
        f"LABEL {LABEL_TOOLCHAIN}={TOOLCHAIN_CMAKE}",
        f"RUN ({tools} ls /usr/include/python3*/Python.h >/dev/null 2>&1) "
        f"|| (apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends {apt} "
        "&& rm -rf /var/lib/apt/lists/*)",
        f"RUN {venv}/bin/pip install {pins}",
        "# the wheels' CMake targets name the wheel builder's Python include folders",
        f"RUN v={ver} && t={tag} && mkdir -p {WHEEL_BUILDER_PYTHON}/$t/include {WHEEL_BUILDER_PYTHON}/$t/lib "
        f"&& ln -sfn /usr/include/python$v {WHEEL_BUILDER_PYTHON}/$t/include/python$v "
        f"&& ln -sfn {venv}/lib/python$v {WHEEL_BUILDER_PYTHON}/$t/lib/python$v",
    ]
