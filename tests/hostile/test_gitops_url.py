"""The GitOps URL (fleet.yaml's ``gitops.repo``, ``export kubernetes --git-repo``) takes robot.yaml's repository
grammar: https, ssh or scp-like, http only when opted in, no option-like user or path; and a refused URL's userinfo
(a token) is never printed (the fourth hostile pass)."""

from __future__ import annotations

import pytest

from robocore.config.fleet import parse_fleet_text
from robocore.config.loader import parse_robot_text
from robocore.config.sources import gitops_url, without_userinfo
from robocore.errors import ConfigError

ROBOT = parse_robot_text("ros_distro: jazzy\nregistry: 10.0.0.2:5000\nhosts:\n  - {name: main, ip: 192.168.1.10}\n"
                         "components:\n  - {name: talker, image: 'ros:jazzy', runs_on: main}\n")
FLEET = "engine: kubernetes\nrobots:\n  - {name: r1, hosts: {main: {ip: 10.0.1.5}}}\n"


def refusal(gitops: str) -> list[str]:
    with pytest.raises(ConfigError) as caught:
        parse_fleet_text(FLEET + gitops, ROBOT)
    return caught.value.lines()


@pytest.mark.parametrize("url, says", [
    ("http://git.example.org/team/fleet.git", "http://"),  # the cases
    ("-oProxyCommand=x@git.example.org:team/fleet.git", "option"),
    ("git@git.example.org:-oProxyCommand=x", "must be a git URL"),
    ("https://ghp_SECRETTOKEN@git.example.org/fleet.git", "names a user"),  # a token as the user: export would
    # commit it
    ("ssh://git@git.example.org/team/fleet.git", None),  # ssh's login name stays (keys authenticate)
    ("git://git.example.org/fleet.git", "git URL; a GitOps controller clones"),  # variants
    ("file:///srv/fleet.git", "file URL"),
    ("ext::sh -c touch% /tmp/x", "ext URL"),
    ("/srv/fleet.git", "file URL"),
])
def test_gitops_repo_takes_robot_yamls_grammar(url: str, says: str | None) -> None:
    text = f"gitops: {{repo: {url!r}}}\n"
    if says is None:  # ssh's user name is allowed (ssh keys authenticate)
        assert parse_fleet_text(FLEET + text, ROBOT).gitops is not None
        return
    lines = refusal(text)
    assert len(lines) == 1 and lines[0].startswith("fleet.yaml:4: gitops.repo: "), lines
    assert says in lines[0] and "SECRETTOKEN" not in lines[0], lines


def test_http_only_when_opted_in() -> None:
    fleet = parse_fleet_text(FLEET + "gitops: {allow_protocol: http, repo: 'http://git.lab/team/fleet.git'}\n", ROBOT)
    assert fleet.gitops is not None and fleet.gitops.repo == "http://git.lab/team/fleet.git"
    assert gitops_url("https://git.lab/team/fleet.git") == "https://git.lab/team/fleet.git"  # negative control
    with pytest.raises(ValueError, match="allow_protocol: http"):
        gitops_url("http://git.lab/team/fleet.git")


@pytest.mark.parametrize("url", ["http://bot:ghp_SECRET@git.example.org/fleet.git",
                                 "https://bot:ghp_SECRET@git.example.org/fleet.git",
                                 "ftp://bot:ghp_SECRET@git.example.org/fleet.git",
                                 "http://ghp_SECRET@git.example.org/fleet.git",
                                 "git://ghp_SECRET@git.example.org/fleet.git",
                                 "ghp_SECRET@git.example.org:-x",
                                 # variants: a token holding "@", a space or a tab (the userinfo ends at the last "@")
                                 "http://bot@ghp_SECRET@git.example.org/fleet.git",
                                 "http://ghp_SE CRET_SECRET@git.example.org/fleet.git",
                                 "https://ghp\tSECRET@git.example.org/fleet.git",
                                 "git://a@SECRET@git.example.org:-x/fleet.git"])
def test_a_refused_urls_userinfo_is_never_printed(url: str) -> None:
    lines = refusal(f"gitops: {{repo: {url!r}}}\n")
    assert len(lines) == 1 and "SECRET" not in lines[0] and "fleet.yaml:4: gitops.repo" in lines[0], lines
    with pytest.raises(ValueError) as caught:
        gitops_url(url)
    assert "SECRET" not in str(caught.value)


def test_without_userinfo_keeps_the_rest() -> None:
    assert without_userinfo("https://u:t@h.example/x.git") == "https://***@h.example/x.git"
    assert without_userinfo("u@h.example:x.git") == "***@h.example:x.git"
    assert without_userinfo("https://h.example/a@b") == "https://h.example/a@b"
    assert without_userinfo("https://h.example?q=a@b") == "https://h.example?q=a@b"
    assert without_userinfo("u@h.example:team/x@y.git") == "***@h.example:team/x@y.git"
    assert without_userinfo("https://a@b c@h.example/x") == "https://***@h.example/x"
