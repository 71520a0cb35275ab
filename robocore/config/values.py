"""Typed robot.yaml values: host addresses, paths, image references, pip requirements, free text.

A robot.yaml often comes from someone else (a colleague, a template, a pull request), and its
values end up in argv lists, Dockerfiles, compose files and remote paths. Each value here has a
grammar instead of being free text, so that nothing a file says can start with ``-`` (be taken
for an option), hold a control character or a newline (start another line of a Dockerfile), or
name something other than what its key means.

Each grammar is one regular expression used twice: :func:`re.fullmatch` in Python decides, and the
same expression (anchored by :func:`schema_pattern`) goes into the JSON Schema, so that an editor
never calls a value fine that ``robocore validate`` refuses. The validator functions only add the
reason a value was refused.
"""

from __future__ import annotations

import ipaddress
import re
from typing import Annotated, Any

from pydantic import AfterValidator, Field, Strict

from robocore.config.host_addresses import refuse_no_machine
from robocore.ui import MAX_SHOWN as MAX_SHOWN
from robocore.ui import shown as shown

_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")
_CONTROL_BUT_NEWLINE_TAB = re.compile(r"[\x00-\x08\x0b-\x1f\x7f-\x9f]")


def has_control(text: str, *, allow_newline_tab: bool = False) -> bool:
    """True when ``text`` holds a control character (C0, DEL or C1); ``allow_newline_tab`` lets ``\\n``/``\\t`` pass."""
    pattern = _CONTROL_BUT_NEWLINE_TAB if allow_newline_tab else _CONTROL
    return pattern.search(text) is not None


def printable(text: str) -> str:
    """``text`` with every non-printable character written as an escape (``\\x1b``, ``\\u202e``)."""
    if text.isprintable():
        return text
    return "".join(ch if ch.isprintable() else repr(ch)[1:-1] for ch in text)


def schema_pattern(core: str) -> str:
    """``core`` anchored for a JSON Schema ``pattern``, which matches with search semantics.

    ``(?!\\n)`` keeps Python's ``$`` (the JSON Schema validators in Python use :mod:`re`) from
    accepting a value with a trailing newline; in ECMA-262 it changes nothing.
    """
    return f"^(?:{core})$(?!\\n)"


def pattern_field(core: str, description: str | None = None) -> Any:
    """The JSON Schema side of a grammar-checked string: its anchored pattern (and a description)."""
    extra: dict[str, Any] = {"pattern": schema_pattern(core)}
    if description is None:
        return Field(json_schema_extra=extra)
    return Field(description=description, json_schema_extra=extra)


def _refuse_common(value: str, what: str) -> None:
    """The reasons every typed value shares: empty, a leading ``-``, a control character."""
    if not value:
        raise ValueError(f"must be {what} (got an empty value)")
    if value.startswith("-"):
        raise ValueError(f"must be {what}, not an option (got {shown(value)})")
    if has_control(value):
        raise ValueError(f"must be {what} without control characters (got {shown(value)})")
    if value != value.strip():
        raise ValueError(f"must be {what} without leading or trailing spaces (got {shown(value)})")


# --- names -------------------------------------------------------------------------------------------

#: Names of hosts, components, common packages (and the hosts ``runs_on`` names).
NAME = r"[A-Za-z][A-Za-z0-9_-]{0,62}"
#: A Linux user name.
USER = r"[a-z_][a-z0-9_.-]{0,31}"


def name(value: str) -> str:
    """``value`` if it is a robocore name: a letter, then letters, digits, ``_`` or ``-`` (at most 63)."""
    if re.fullmatch(NAME, value):
        return value
    raise ValueError(f"{shown(value)} is not a valid value here (expected a letter, then letters, digits, '_' or '-' "
                     "(at most 63))")


def user_name(value: str) -> str:
    """``value`` if it is a Linux user name (lower case, digits, ``_``, ``-``, ``.``; at most 32)."""
    if re.fullmatch(USER, value):
        return value
    raise ValueError(f"{shown(value)} is not a valid value here (expected a Linux user name: lower case, digits, "
                     "'_', '-' or '.')")


Name = Annotated[str, AfterValidator(name), pattern_field(
    NAME, "Identifier: a letter, then letters, digits, '_' or '-'.",
)]
UserName = Annotated[str, AfterValidator(user_name), pattern_field(USER)]


# --- host addresses -----------------------------------------------------------------------------

_OCTET = r"(?:25[0-5]|2[0-4][0-9]|1[0-9]{2}|[1-9]?[0-9])"
IPV4 = rf"{_OCTET}(?:\.{_OCTET}){{3}}"
_H16 = r"[0-9A-Fa-f]{1,4}"
_LS32 = rf"(?:{_H16}:{_H16}|{IPV4})"
#: An IPv6 address without a zone (RFC 4291 section 2.2, as in RFC 3986's IPv6address).
IPV6 = "(?:" + "|".join([
    rf"(?:{_H16}:){{6}}{_LS32}",
    rf"::(?:{_H16}:){{5}}{_LS32}",
    rf"(?:{_H16})?::(?:{_H16}:){{4}}{_LS32}",
    rf"(?:(?:{_H16}:){{0,1}}{_H16})?::(?:{_H16}:){{3}}{_LS32}",
    rf"(?:(?:{_H16}:){{0,2}}{_H16})?::(?:{_H16}:){{2}}{_LS32}",
    rf"(?:(?:{_H16}:){{0,3}}{_H16})?::{_H16}:{_LS32}",
    rf"(?:(?:{_H16}:){{0,4}}{_H16})?::{_LS32}",
    rf"(?:(?:{_H16}:){{0,5}}{_H16})?::{_H16}",
    rf"(?:(?:{_H16}:){{0,6}}{_H16})?::",
]) + ")"
_LABEL = r"[A-Za-z0-9](?:[A-Za-z0-9-]{0,61}[A-Za-z0-9])?"
#: One to four numbers in C's ``inet_aton`` forms (decimal, ``0``-octal, ``0x``-hex) joined by dots: what ssh,
#: Docker and every resolver read as an IPv4 address (``0x7f000001`` and ``0x7f.1`` are 127.0.0.1), never a name.
IPV4_NUMBERS = r"(?:(?:0[xX][0-9A-Fa-f]*|[0-9]+)\.){0,3}(?:0[xX][0-9A-Fa-f]*|[0-9]+)(?![A-Za-z0-9.-])"
#: An RFC 1123 host name of at most 253 characters whose last label is not all digits (so that it
#: cannot be mistaken for a short IPv4 address such as ``10.1``) and that is not an IPv4 address written as numbers
#: (:data:`IPV4_NUMBERS`: the loopback and "any" rules, and the comparison of addresses, would not see it). Usable
#: inside a URL too.
HOSTNAME = (rf"(?=[A-Za-z0-9.-]{{1,253}}(?![A-Za-z0-9.-]))(?!{IPV4_NUMBERS})"
            rf"(?:{_LABEL}\.)*(?=[0-9]*[A-Za-z-]){_LABEL}(?![A-Za-z0-9.-])")
HOST_ADDRESS = f"{IPV4}|{IPV6}|{HOSTNAME}"


def host_address(value: str) -> str:
    """``value`` if it is an IPv4 address, an IPv6 address (no zone) or an RFC 1123 host name."""
    what = "an IP address or a host name"
    _refuse_common(value, what)
    if re.fullmatch(HOST_ADDRESS, value):
        refuse_no_machine(value)
        return value
    if "%" in value and _is_ip(value.split("%", 1)[0]):
        raise ValueError(f"must be {what}; zone indexes (%eth0) are not supported (got {shown(value)})")
    if "@" in value:
        raise ValueError(f"must be {what}; the user goes in 'user:' (got {shown(value)})")
    if re.fullmatch(IPV4_NUMBERS, value):
        address = _numbers_as_ipv4(value)
        raise ValueError(f"must be {what}; {shown(value)} is an IPv4 address written as numbers, which ssh and Docker "
                         f"read as {address}: write {address}" if address else
                         f"must be {what}; {shown(value)} is numbers like an IPv4 address, but out of range")
    if len(value) > 253:
        raise ValueError(f"must be {what} of at most 253 characters (got {len(value)} characters)")
    raise ValueError(f"must be {what} (got {shown(value)})")


def _numbers_as_ipv4(text: str) -> str | None:
    """The IPv4 address C's ``inet_aton`` reads ``text`` (:data:`IPV4_NUMBERS`) as; None when a number is out of
    range."""
    import socket

    try:
        return socket.inet_ntoa(socket.inet_aton(text))
    except OSError:
        return None


def _is_ip(text: str) -> bool:
    try:
        ipaddress.ip_address(text)
    except ValueError:
        return False
    return True


def is_ipv6(address: str) -> bool:
    """True when ``address`` is an IPv6 address literal (not a host name, not IPv4), so that a tool that reads
    ``host:port`` or ``host:path`` needs it in brackets.

    A zone (``fe80::1%eth0``) is part of the address (RFC 4007 section 11); brackets are not (``[::1]`` is how a
    URL writes an address, and ``plan.addresses.bare`` removes them).
    """
    try:
        return isinstance(ipaddress.ip_address(address), ipaddress.IPv6Address)
    except ValueError:
        return False


HostAddress = Annotated[str, AfterValidator(host_address), pattern_field(
    HOST_ADDRESS, "Address used for SSH, rsync and Docker: an IPv4 or IPv6 address or an RFC 1123 "
    "host name (no user@, no port, no spaces). DDS discovery over IPv6 is not supported yet.",
)]


# --- paths on a host --------------------------------------------------------------------------------

_PATH_SEGMENT = r"(?!\.\.?(?:/|$))[A-Za-z0-9._@%+=,~-]+"
#: A normalised absolute folder (no ``//``, no ``.`` or ``..`` segments, not ``/`` itself), optionally with one
#: trailing ``/`` (dropped).
ABSOLUTE_FOLDER_INPUT = rf"(?=.{{2,1025}}$)(?:/{_PATH_SEGMENT})+/?"


def absolute_folder(value: str) -> str:
    """``value`` without its trailing ``/`` if it is a normalised absolute folder other than ``/`` (letters,
    digits and ``._@%+=,~-``)."""
    what = "a normalised absolute folder such as /opt/robot"
    if re.fullmatch(ABSOLUTE_FOLDER_INPUT, value):
        return value.removesuffix("/")
    if has_control(value):
        raise ValueError(f"must be {what} without control characters (got {shown(value)})")
    if not value.startswith("/"):
        raise ValueError(f"must be an absolute path (got {shown(value)})")
    if value.strip("/") == "":
        raise ValueError(f"must be a folder below / (got {shown(value)})")
    if len(value) > 1024:
        raise ValueError(f"must be {what} of at most 1024 characters (got {len(value)} characters)")
    if any(part in (".", "..", "") for part in value[1:].removesuffix("/").split("/")):
        raise ValueError(f"must be {what}: no '.', '..', '//' or trailing '/' (got {shown(value)})")
    raise ValueError(f"must be {what} (letters, digits and . _ @ % + = , ~ - only; got {shown(value)})")


MountRoot = Annotated[str, AfterValidator(absolute_folder), pattern_field(
    ABSOLUTE_FOLDER_INPUT, "Absolute folder on the host that receives synced install trees (default "
    "/home/<user>/robocore, /root/robocore for root); normalised, not /.",
)]


# --- image references ----------------------------------------------------------------------------

_ALNUM = r"[a-z0-9]+"
_SEPARATOR = r"(?:[._]|__|-+)"
_PATH_COMPONENT = rf"{_ALNUM}(?:{_SEPARATOR}{_ALNUM})*"
_DOMAIN_COMPONENT = r"(?:[A-Za-z0-9]|[A-Za-z0-9][A-Za-z0-9-]*[A-Za-z0-9])"
_PORT = r"[0-9]{1,5}"
#: A registry host: dotted (``ghcr.io``, ``10.0.0.5``) or ``localhost``, each with an optional port, or any
#: single name with a port (``myregistry:5000``); Docker's rule for telling a registry from a path.
_DOMAIN = (
    rf"(?:(?:{_DOMAIN_COMPONENT}(?:\.{_DOMAIN_COMPONENT})+|localhost)(?::{_PORT})?|{_DOMAIN_COMPONENT}:{_PORT})"
)
#: The path of an image name (no registry, tag or digest): lower-case components separated by '/'.
IMAGE_PATH = rf"{_PATH_COMPONENT}(?:/{_PATH_COMPONENT})*"
_NAME = rf"(?:{_DOMAIN}/)?{IMAGE_PATH}"
_TAG = r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,127}"
_DIGEST = r"[A-Za-z][A-Za-z0-9]*(?:[-_+.][A-Za-z][A-Za-z0-9]*)*:[0-9a-fA-F]{32,}"
#: Docker's reference grammar: ``[registry[:port]/]path[:tag][@digest]``, path in lower case, 255 characters at most.
IMAGE_REF = rf"(?=.{{1,255}}$){_NAME}(?::{_TAG})?(?:@{_DIGEST})?"
#: Where images are pushed: ``registry[:port][/path]`` or a Docker Hub namespace, optionally ending in ``/``.
REGISTRY = rf"(?=.{{1,200}}$)(?:{_DOMAIN}|{_PATH_COMPONENT})(?:/{_PATH_COMPONENT})*/?"
#: Text that, followed by a component name, is a valid image path (``myrobot-``, ``org/robot-``).
IMAGE_PREFIX = (
    rf"(?=.{{0,128}}$)(?:{_PATH_COMPONENT}/)*(?:{_PATH_COMPONENT}{_SEPARATOR}?)?"
)


def image_ref(value: str) -> str:
    """``value`` if it is a Docker image reference (``[registry[:port]/]path[:tag][@digest]``)."""
    what = "an image reference such as ros:jazzy-ros-base or ghcr.io/org/image:tag"
    _refuse_common(value, what)
    if re.fullmatch(IMAGE_REF, value):
        return value
    if len(value) > 255:
        raise ValueError(f"must be an image reference of at most 255 characters (got {len(value)} characters)")
    if re.fullmatch(IMAGE_REF, value.lower()):
        raise ValueError(f"must be {what}; the image path must be lower case (got {shown(value)})")
    raise ValueError(f"must be {what} (got {shown(value)})")


def registry(value: str) -> str:
    """``value`` if it names a registry (``registry.example.com:5000/team``) images can be pushed to."""
    what = "a registry such as ghcr.io/org or localhost:5000"
    _refuse_common(value, what)
    if re.fullmatch(REGISTRY, value):
        return value
    raise ValueError(f"must be {what} (got {shown(value)})")


def image_prefix(value: str) -> str:
    """``value`` if a component name after it makes a valid image path (``myrobot-``, ``team/robot-``)."""
    if re.fullmatch(IMAGE_PREFIX, value):
        return value
    raise ValueError(
        f"{shown(value)} is not a valid value here (expected lower-case letters and digits, separated by "
        "'.', '_', '-' or '/', at most 128)"
    )


ImageRef = Annotated[str, AfterValidator(image_ref), pattern_field(
    IMAGE_REF, "A Docker image reference: [registry[:port]/]path[:tag][@digest], path in lower case.",
)]
Registry = Annotated[str, AfterValidator(registry), pattern_field(
    REGISTRY, "Registry images are pushed to (registry[:port][/path]); without one, images are "
    "streamed to hosts.",
)]
ImagePrefix = Annotated[str, AfterValidator(image_prefix), pattern_field(
    IMAGE_PREFIX, "Prefix of every image name: lower-case letters and digits separated by '.', '_', "
    "'-' or '/' (e.g. myrobot- or team/robot-).",
)]


# --- git repositories (GitOps) ---------------------------------------------------------------------------

#: A folder inside a git repository: relative, '/'-separated, no '.' or '..' part (empty: the top).
_GIT_PART = r"(?!\.\.?(?:/|$))[A-Za-z0-9._~+-]+"
GIT_FOLDER = rf"(?=.{{0,1024}}$)(?:{_GIT_PART}(?:/{_GIT_PART})*)?"


def git_folder(value: str) -> str:
    """``value`` if it is a folder inside a git repository (relative, no '.' or '..' part; empty: the top)."""
    stripped = value.strip("/")
    if re.fullmatch(GIT_FOLDER, stripped) and not has_control(value):
        return value
    raise ValueError(f"must be a relative folder of the repository such as fleet/k8s, with no '.' or '..' part "
                     f"(got {shown(value)})")


GitFolder = Annotated[str, AfterValidator(git_folder), pattern_field(
    r"/*" + GIT_FOLDER + r"/*", "A folder inside the repository (relative, no '.' or '..' part; empty: its top).")]


# --- packages -----------------------------------------------------------------------------------------

#: A Debian package name with an optional ``=version`` or ``/release``.
APT_PACKAGE = r"[a-z0-9][a-z0-9+.-]+(?:=[A-Za-z0-9.+:~-]+|/[a-z0-9][a-z0-9.+-]*)?"


def apt_package(value: str) -> str:
    """``value`` if it is a Debian package name, optionally ``=version`` or ``/release``."""
    what = "a Debian package name (lower case), optionally =version or /release"
    _refuse_common(value, what)
    if re.fullmatch(APT_PACKAGE, value):
        return value
    raise ValueError(f"{shown(value)} is not a valid value here (expected {what})")


_PEP508_NAME = r"[A-Za-z0-9](?:[A-Za-z0-9._-]*[A-Za-z0-9])?"
_RELEASE = r"[0-9]+(?:\.[0-9]+)*"
_PUBLIC_VERSION = rf"{_RELEASE}(?:(?:a|b|rc)[0-9]+)?(?:\.post[0-9]+)?(?:\.dev[0-9]+)?"
_SPECIFIER = (
    rf"(?:(?:==|!=){_RELEASE}\.\*|(?:==|!=|<=|>=|<|>){_PUBLIC_VERSION}"
    rf"|~={_RELEASE}\.[0-9]+(?:(?:a|b|rc)[0-9]+)?(?:\.post[0-9]+)?(?:\.dev[0-9]+)?)"
)
#: The editor's view of a pip entry: name, extras, version specifiers, no spaces. robocore itself
#: accepts every PEP 508 requirement (markers, URLs), which is more than a pattern can say.
PIP_SIMPLE = (
    rf"(?=.{{1,1000}}$){_PEP508_NAME}(?:\[{_PEP508_NAME}(?:,{_PEP508_NAME})*\])?(?:{_SPECIFIER}(?:,{_SPECIFIER})*)?"
)


def pip_requirement(value: str) -> str:
    """``value`` if it is a PEP 508 requirement (``numpy>=1.26``, ``pkg[extra]; python_version<'3.12'``)."""
    from packaging.requirements import InvalidRequirement, Requirement

    what = "a pip requirement (PEP 508) such as numpy>=1.26"
    _refuse_common(value, what)
    if len(value) > 1000:
        raise ValueError(f"must be {what} of at most 1000 characters (got {len(value)} characters)")
    try:
        Requirement(value)
    except InvalidRequirement as exc:
        reason = str(exc).splitlines()[0] if str(exc) else "not PEP 508"
        raise ValueError(f"must be {what} (got {shown(value)}: {printable(reason)[:100]})") from None
    return value


AptPackage = Annotated[str, AfterValidator(apt_package), pattern_field(
    APT_PACKAGE, "A Debian package: name, name=version or name/release.",
)]
PipRequirement = Annotated[str, AfterValidator(pip_requirement), pattern_field(
    PIP_SIMPLE, "A pip requirement (PEP 508): name[extras] with version specifiers, markers or "
    "a URL.",
)]


# --- environment ------------------------------------------------------------------------------------

#: A POSIX environment variable name.
ENV_NAME = r"[A-Za-z_][A-Za-z0-9_]{0,255}"


def env_name(value: str) -> str:
    """``value`` if it is a POSIX environment variable name (letters, digits, ``_``; no leading digit)."""
    if re.fullmatch(ENV_NAME, value):
        return value
    raise ValueError(f"{shown(value)} is not a valid environment variable name (letters, digits and '_', "
                     "not starting with a digit)")


EnvName = Annotated[str, AfterValidator(env_name), pattern_field(ENV_NAME)]


# --- free text ----------------------------------------------------------------------------------------

#: One line of text: no control characters at all.
ONE_LINE = r"[^\x00-\x1f\x7f-\x9f]*"
#: Text that may span lines (``\n`` and ``\t`` allowed), without other control characters.
MULTI_LINE = r"[^\x00-\x08\x0b-\x1f\x7f-\x9f]*"


def one_line(value: str) -> str:
    """``value`` if it holds no control character (no newline either)."""
    if has_control(value):
        raise ValueError(f"must be one line of text without control characters (got {shown(value)})")
    return value


def multi_line(value: str) -> str:
    """``value`` if its only control characters are newlines and tabs."""
    if has_control(value, allow_newline_tab=True):
        raise ValueError(f"must be text without control characters other than newline and tab (got {shown(value)})")
    return value


OneLine = Annotated[str, AfterValidator(one_line), pattern_field(ONE_LINE)]


def shell_words(value: str) -> str:
    """``value`` if it is one line that splits into words as a shell would (no unbalanced quote)."""
    import shlex

    one_line(value)
    try:
        shlex.split(value)
    except ValueError as exc:  # "No closing quotation", "No escaped character"
        raise ValueError(f"is split into words as a shell would, and {shown(value)} cannot be: {exc}") from None
    return value


_CHAR = r"[^\x00-\x1f\x7f-\x9f"  # one-line characters, each use below closes the class
#: One line of shell words in :func:`shlex.split`'s (POSIX) quoting: plain characters, a backslash and the
#: character it escapes, '...' (no escapes inside), "..." (backslash escapes inside). Each alternative starts
#: with a character of its own, so matching is linear; quotes are not escaped (ECMA's unicode mode refuses that).
SHELL_WORDS = "(?:" + "|".join([
    _CHAR + "'\"\\\\]",  # a plain character
    r"\\" + _CHAR + "]",  # an escaped one
    "'" + _CHAR + "']*'",
    '"(?:' + _CHAR + '"\\\\]|\\\\' + _CHAR + ']' + ')*"',
]) + ")*"

#: A command line written as text (entrypoint, launch arguments): split into words with shell quoting rules.
ShellWords = Annotated[str, AfterValidator(shell_words), pattern_field(SHELL_WORDS)]
#: A whole number that YAML wrote as a number: ``true``/``false`` (YAML booleans) are not 1 and 0, and ``"5"`` is
#: not 5. ``5.0`` is 5 (:class:`robocore.config.strict.Strict`, every model's base).
Number = Annotated[int, Strict()]
MultiLine = Annotated[str, AfterValidator(multi_line), pattern_field(MULTI_LINE)]
