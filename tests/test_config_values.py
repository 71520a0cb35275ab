"""Typed robot.yaml values: what each grammar accepts and refuses, and that the JSON Schema's pattern
and robocore's validator agree on every string (an editor never calls a value fine that validate refuses)."""

from __future__ import annotations

import ipaddress
import re
from collections.abc import Callable

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from robocore.config import sources, values
from robocore.config.host_addresses import names_no_machine
from robocore.config.mappings import device_problem, port_problem, volume_problem
from robocore.config.sources import git_protocol, git_ref_problem, protocol_problem
from robocore.config.values import schema_pattern

AGREEMENT = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
TRICKY = "-.:/@_~^[]{}$;` \t\n\x00\x1b%+=,?*#\\'\"aZ09\u202e\u00e9"


def accepts(validator: Callable[[str], str], value: str) -> bool:
    try:
        validator(value)
    except ValueError:
        return False
    return True


def near(core: str) -> st.SearchStrategy[str]:
    """Strings that match ``core``, the same with a tricky character added or one removed, and noise.

    Length limits (``(?=.{1,255}$)``) are left out of what is generated: hypothesis meets lookaheads by
    filtering, which is slow; the agreement is still checked on every string, long ones included."""
    matching = st.from_regex(re.sub(r"\(\?=\.\{[0-9,]+\}\$\)", "", core), fullmatch=True)

    @st.composite
    def mutated(draw: st.DrawFn) -> str:
        text = draw(matching)
        where = draw(st.integers(min_value=0, max_value=len(text)))
        if text and draw(st.booleans()):
            return text[:where] + text[where + 1:]
        return text[:where] + draw(st.sampled_from(TRICKY)) + text[where:]

    return st.one_of(matching, mutated(), st.text(alphabet=TRICKY, max_size=12), st.text(max_size=12))


GRAMMARS = {
    "host-address": (values.HOST_ADDRESS, values.host_address),
    "image-reference": (values.IMAGE_REF, values.image_ref),
    "registry": (values.REGISTRY, values.registry),
    "image-prefix": (values.IMAGE_PREFIX, values.image_prefix),
    "apt-package": (values.APT_PACKAGE, values.apt_package),
    "env-name": (values.ENV_NAME, values.env_name),
    "git-url": (sources.GIT_URL, sources.git_url),
    "git-ref": (sources.GIT_REF, sources.git_ref),
    "checkout-folder": (sources.CHECKOUT_FOLDER, sources.checkout_folder),
}


@pytest.mark.parametrize("name", sorted(GRAMMARS))
def test_the_schema_pattern_and_the_validator_agree(name: str) -> None:
    core, validator = GRAMMARS[name]
    pattern = schema_pattern(core)

    @AGREEMENT
    @given(near(core))
    def agree(value: str) -> None:
        # the unspecified and IPv4-mapped loopback addresses match the pattern (a syntax) and name no machine
        assume(not (name == "host-address" and names_no_machine(value)))
        assert (re.search(pattern, value) is not None) == accepts(validator, value), repr(value)

    agree()


@AGREEMENT
@given(st.one_of(st.lists(st.sampled_from(["srv", "robot", "a.b", "x-y", "..", ".", "", "~", "a b", "$x"]),
                          max_size=4).map(lambda parts: "/" + "/".join(parts)),
                 st.text(alphabet="/.a-~ \n", max_size=12)))
def test_mount_root_pattern_and_validator_agree(value: str) -> None:
    pattern = schema_pattern(values.ABSOLUTE_FOLDER_INPUT)
    assert (re.search(pattern, value) is not None) == accepts(values.absolute_folder, value), repr(value)


@AGREEMENT
@given(near(values.PIP_SIMPLE))
def test_what_the_schema_calls_a_pip_entry_is_a_pep_508_requirement(value: str) -> None:
    if re.search(schema_pattern(values.PIP_SIMPLE), value):
        assert accepts(values.pip_requirement, value), repr(value)


@AGREEMENT
@given(st.ip_addresses(v=6))
def test_every_ipv6_address_is_accepted_in_both_its_forms(address: ipaddress.IPv6Address) -> None:
    assume(not names_no_machine(str(address)))  # refused: "any" and loopback written as IPv4-mapped
    for text in (str(address), address.exploded):
        assert values.host_address(text) == text and values.is_ipv6(text)


@AGREEMENT
@given(near(values.IPV6))
def test_what_the_ipv6_grammar_accepts_python_parses(value: str) -> None:
    if re.fullmatch(values.IPV6, value):
        assert ipaddress.ip_address(value).version == 6


@AGREEMENT
@given(st.text(alphabet="ab./-@{}~^:lock \x01", max_size=10))
def test_the_ref_rules_and_the_ref_grammar_agree(value: str) -> None:
    assert (git_ref_problem(value) is None) == (re.fullmatch(sources.GIT_REF, value) is not None), repr(value)


@pytest.mark.parametrize("value", [
    "192.168.1.10", "10.0.0.255", "pi5.local", "robot-1", "localhost", "ROBOT.example.com", "::1", "fe80::1",
    "2001:db8::5", "::ffff:192.168.1.1", "a" * 63 + ".local", "x1",
])
def test_host_addresses_accepted(value: str) -> None:
    assert values.host_address(value) == value


@pytest.mark.parametrize("value", [
    "-oProxyCommand=id", "$(id)", "a;id", "root@10.0.0.1", "\x1b[31m", "a" * 100_000, "10.1", "1.2.3.4.5",
    "999.1.1.1", "01.2.3.4", "host_1", "-host", "host-", "[::1]", "10.0.0.1:22", "", " pi", "fe80::1%eth0", "a..b",
    "x.", "a" * 64,
])
def test_host_addresses_refused(value: str) -> None:
    with pytest.raises(ValueError, match="must be an IP address or a host name"):
        values.host_address(value)


@pytest.mark.parametrize("value", [
    "ros:jazzy-ros-base", "busybox", "ghcr.io/tiryoh/ros2-desktop-vnc:humble", "localhost:5000/a/b:v1",
    "127.0.0.1:5000/robot-talker:v1", "registry.local:5000/x", "debian@sha256:" + "a" * 64, "a__b", "a---b:T_1.x",
    "my.registry/org/img:tag@sha256:" + "0" * 64,
])
def test_image_references_accepted(value: str) -> None:
    assert values.image_ref(value) == value


@pytest.mark.parametrize("value", [
    "debian\nRUN id", "-it", "Debian:12", "debian:bookworm slim", "debian@sha256:abc", "debian:", "a/-b", "a//b",
    "a..b", ":tag", "img:-x", "img:" + "t" * 129, "a" * 256, "UPPER/case", "x/y_", "$(id)",
])
def test_image_references_refused(value: str) -> None:
    with pytest.raises(ValueError):
        values.image_ref(value)


def test_an_upper_case_image_path_is_told_so() -> None:
    with pytest.raises(ValueError, match="must be lower case"):
        values.image_ref("ghcr.io/Team/image:v1")


@pytest.mark.parametrize("value, ok", [
    ("docker.io/dragomirxyz", True), ("localhost:5000", True), ("ghcr.io/org/", True), ("team", True),
    ("127.0.0.1:5000", True), ("-x", False), ("reg.io/Team", False), ("reg.io//x", False), ("a b", False),
])
def test_registries(value: str, ok: bool) -> None:
    assert accepts(values.registry, value) is ok


@pytest.mark.parametrize("value, ok", [
    ("", True), ("myrobot-", True), ("lekiwiv2-arm64-", True), ("team/robot-", True), ("a.b_", True), ("x", True),
    ("Demo-", False), ("-x", False), ("../x", False), ("a//", False), ("/x", False), ("x;y", False), ("a--", True),
])
def test_image_prefixes(value: str, ok: bool) -> None:
    assert accepts(values.image_prefix, value) is ok


@pytest.mark.parametrize("value, ok", [
    ("curl", True), ("ros-jazzy-tf2-ros", True), ("libfoo1=1.2-3ubuntu1", True), ("python3-pip/bookworm-backports",
                                                                                   True),
    ("g++", True), ("x", False), ("-o", False), ("-o APT::Update::Pre-Invoke::=id", False), ("curl;id", False),
    ("Curl", False), ("curl=1.0 evil", False), ("curl\n", False),
])
def test_apt_packages(value: str, ok: bool) -> None:
    assert accepts(values.apt_package, value) is ok


@pytest.mark.parametrize("value, ok", [
    ("numpy", True), ("numpy>=1.26", True), ("pkg[extra]==1.0", True), ("pkg; python_version<'3.12'", True),
    ("pkg @ https://example.com/pkg-1.0-py3-none-any.whl", True), ("ros-jazzy-rclpy[fastrtps]", True),
    ("--index-url=http://x", False), ("-r/etc/passwd", False), ("-e .", False), ("numpy; touch x", False),
    ("numpy\nRUN id", False), ("", False), (" numpy", False),
])
def test_pip_requirements(value: str, ok: bool) -> None:
    assert accepts(values.pip_requirement, value) is ok


@pytest.mark.parametrize("url, protocol", [
    ("https://github.com/ros/common_msgs.git", "https"),
    ("https://git@github.com:443/ros/x", "https"),
    ("ssh://git@github.com/ros/x.git", "ssh"),
    ("ssh://[2001:db8::1]:2222/x", "ssh"),
    ("git@github.com:ros/x.git", "ssh"),
    ("github.com:ros/x", "ssh"),
    ("http://mirror.local/x.git", "http"),
    ("git://github.com/x/y", "git"),
    ("file:///srv/git/x.git", "file"),
    ("/srv/git/x.git", "file"),
    ("./vendor/x", "file"),
    ("ext::ssh -i key host %S 'repo'", "ext"),
])
def test_git_urls_and_their_protocols(url: str, protocol: str) -> None:
    assert git_protocol(url) == protocol
    allowed = protocol in sources.DEFAULT_PROTOCOLS
    assert (protocol_problem(url, None) is None) is allowed
    assert protocol_problem(url, protocol) is None


def test_allowed_protocols_are_the_defaults_plus_the_opt_in() -> None:
    assert sources.allowed_protocols(None) == ("https", "ssh")
    assert sources.allowed_protocols("file") == ("https", "ssh", "file")


@pytest.mark.parametrize("url, reason", [
    ("--upload-pack=id", "not an option"),
    ("-u id", "not an option"),
    ("fd::17", "remote helper 'fd'"),
    ("https://user:secret@github.com/x", "must not hold a password"),
    ("ftp://host/x", "scheme 'ftp'"),
    ("https://github.com/x y", "without spaces"),
    ("https://github.com/\x1b[2J", "control characters"),
    ("ssh://-oProxyCommand=id/x", "must be a git URL"),
    ("host:-oProxyCommand=id", "must be a git URL"),
    ("host::path", "remote helper"),
    ("repo", "must be a git URL"),
    ("", "not empty"),
])
def test_git_urls_refused(url: str, reason: str) -> None:
    with pytest.raises(ValueError, match=re.escape(reason)):
        git_protocol(url)


@pytest.mark.parametrize("ref, ok", [
    ("main", True), ("humble", True), ("v1.2.3", True), ("feature/x-y_z", True), ("a" * 40, True),
    ("0123abc", True), ("release+1", True), ("user@host", True),
    ("-b", False), ("--upload-pack=x", False), ("a..b", False), ("a/.b", False), (".a", False), ("a.lock", False),
    ("a.lock/b", False), ("a b", False), ("a~1", False), ("a^", False), ("a:b", False), ("a?", False),
    ("a*", False), ("a[", False), ("a\\b", False), ("/a", False), ("a/", False), ("a//b", False), ("a.", False),
    ("@", False), ("a@{1}", False), ("", False), ("a\n", False), ("$(id)", False),
])
def test_git_refs(ref: str, ok: bool) -> None:
    assert (git_ref_problem(ref) is None and re.fullmatch(sources.GIT_REF, ref) is not None) is ok


@pytest.mark.parametrize("url, folder", [
    ("https://github.com/ros/common_msgs.git", "common_msgs"),
    ("git@github.com:ros/x.git", "x"),
    ("https://github.com/x/y/", "y"),
    ("https://github.com/x/..", ".."),
    ("https://github.com/x/.git", ""),
])
def test_default_checkout_folders(url: str, folder: str) -> None:
    assert sources.default_folder(url) == folder
    assert (sources.checkout_folder_problem(folder) is None) is (folder not in ("..", ""))


@pytest.mark.parametrize("value, ok", [
    ("/dev/ttyUSB0", True), ("/dev/ttyUSB0:/dev/ttyUSB0", True), ("/dev/video0:/dev/video0:rw", True),
    ("/dev:/dev", True), ("/etc/shadow", False), ("/dev/../etc", False), ("ttyUSB0", False),
    ("/dev/x:/dev/x:rwx", False), ("/dev/x:/dev/x:rr", False), ("/dev/x:y", False), ("/dev//x", False),
])
def test_devices(value: str, ok: bool) -> None:
    assert (device_problem(value) is None) is ok


@pytest.mark.parametrize("value, ok", [
    ("./config:/config:ro", True), ("../data:/data", False), ("./../data:/d", False),
    (".//x/../..:/d", False), ("logs:/logs", True), ("/srv/x:/x:rw", True),
    ("/:/host", True), ("~/.ssh:/root/.ssh", False), ("/srv/x:/", False), ("/srv/../x:/x", False),
    ("./x:../y", False), ("./x:/y:rox", False), ("a b:/x", False), ("/x", False), ("/x:/y:ro:z", False),
])
def test_volumes(value: str, ok: bool) -> None:
    assert (volume_problem(value) is None) is ok


@pytest.mark.parametrize("value, ok", [
    ("80:80", True), ("[::1]:53:53/udp", True), ("127.0.0.1:8080:80", True), ("80:80\n", False),
    ("999.1.1.1:80:80", False), ("-p 80:80", False), ("0.0.0.0:80:80;x", False),
])
def test_ports(value: str, ok: bool) -> None:
    assert (port_problem(value) is None) is ok


def test_shown_values_escape_control_characters_and_stay_short() -> None:
    assert values.shown("\x1b[31mred") == "'\\x1b[31mred'"
    text = values.shown("a" * 1000)
    assert len(text) <= values.MAX_SHOWN + 30 and text.endswith("... (1,000 characters)")
    assert values.printable("a\u202eb\x07") == "a\\u202eb\\x07"


@pytest.mark.parametrize(("address", "expected"), [
    ("fe80::1", True),
    ("::ffff:192.0.2.1", True),
    # An address with a zone is an IPv6 address (RFC 4007 section 11): a tool needs it in brackets too.
    ("fe80::1%eth0", True),
    # Brackets are how a URL writes an address, not part of it.
    ("[2001:db8::8]", False),
    ("10.0.0.5", False),
    ("robot.local", False),
    ("fe80::1%", False),
])
def test_is_ipv6_answers_for_the_address_itself(address: str, expected: bool) -> None:
    assert values.is_ipv6(address) is expected


def test_bracketed_writes_each_ipv6_form_in_brackets_once() -> None:
    from robocore.plan.addresses import bracketed

    assert [bracketed(a) for a in ("fe80::1%eth0", "[2001:db8::8]", "2001:db8::8", "10.0.0.5")] == [
        "[fe80::1%eth0]", "[2001:db8::8]", "[2001:db8::8]", "10.0.0.5"]
