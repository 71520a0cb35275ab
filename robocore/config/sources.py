"""Git sources in robot.yaml: repository URLs, versions (ref names) and checkout folders.

robocore fetches ``repositories`` and ``common_packages[].repo`` with git on the developer's
machine, so these values decide what git does there. A URL is one of a few known forms and
nothing else: ``https://``, ``ssh://`` and scp-like ``user@host:path`` are fetched as they are;
``http://`` and ``git://`` (neither encrypted nor authenticated), ``file://`` and local paths (this
machine's files) and ``ext::`` (runs a command on this machine) only when the entry says
``allow_protocol: <name>``. Other remote helpers (``name::address``), options (``--upload-pack=``)
and passwords in URLs are refused. Versions are git ref names (the rules of ``git
check-ref-format``) or commit ids, in a conservative character set.
"""

from __future__ import annotations

import re
from typing import Annotated, Any, Literal

from pydantic import AfterValidator

from robocore.config.values import HOSTNAME, IPV4, IPV6, has_control, pattern_field, schema_pattern, shown

#: Protocols fetched without an opt-in.
DEFAULT_PROTOCOLS = ("https", "ssh")
#: Protocols an entry may opt into with ``allow_protocol``.
GitOptIn = Literal["http", "git", "file", "ext"]
OPT_IN_PROTOCOLS: tuple[str, ...] = ("http", "git", "file", "ext")

_USER = r"[A-Za-z0-9_][A-Za-z0-9._-]*"
_URL_HOST = rf"(?:{IPV4}|\[{IPV6}\]|{HOSTNAME})"
_URL_PORT = r"(?:[1-9][0-9]{0,3}|[1-5][0-9]{4}|6[0-4][0-9]{3}|65[0-4][0-9]{2}|655[0-2][0-9]|6553[0-5])"
_AUTHORITY = rf"(?:{_USER}@)?{_URL_HOST}(?::{_URL_PORT})?"
_PATH = r"(?:/[!-~]*)?"
_SCP_HOST = rf"(?:{IPV4}|{HOSTNAME})"

#: Each form of URL robocore accepts, with the protocol git uses for it. Printable ASCII without
#: spaces (only ``ext::`` commands have spaces), no password, no option.
URL_FORMS: dict[str, tuple[str, str]] = {
    "https": ("https", rf"https://{_AUTHORITY}{_PATH}"),
    "ssh": ("ssh", rf"ssh://{_AUTHORITY}{_PATH}"),
    "scp": ("ssh", rf"(?:{_USER}@)?{_SCP_HOST}:(?![-:]|//)[!-~]+"),
    "http": ("http", rf"http://{_AUTHORITY}{_PATH}"),
    "git": ("git", rf"git://{_URL_HOST}(?::{_URL_PORT})?{_PATH}"),
    "file-url": ("file", r"file://[!-~]+"),
    "local-path": ("file", r"(?:/|\./|\.\./)[!-~]*"),
    "ext": ("ext", r"ext::[!-~](?:[ -~]*[!-~])?"),
}
_MAX_URL = r"(?=.{1,2048}$)"
#: Every URL robocore can fetch (with the right ``allow_protocol``).
GIT_URL = _MAX_URL + "(?:" + "|".join(regex for _, regex in URL_FORMS.values()) + ")"
#: The URLs fetched without an opt-in.
DEFAULT_GIT_URL = _MAX_URL + "(?:" + "|".join(
    regex for protocol, regex in URL_FORMS.values() if protocol in DEFAULT_PROTOCOLS
) + ")"


def url_pattern(protocol: str) -> str:
    """The forms of URL that use ``protocol`` (for the schema's per-``allow_protocol`` rules)."""
    return _MAX_URL + "(?:" + "|".join(regex for p, regex in URL_FORMS.values() if p == protocol) + ")"


def git_protocol(url: str) -> str:
    """The protocol git would use for ``url`` (https, ssh, http, git, file or ext); ValueError when robocore
    refuses the URL."""
    if len(url) <= 2048:
        for protocol, regex in URL_FORMS.values():
            if re.fullmatch(regex, url):
                return protocol
    raise ValueError(_why_not_a_url(url))


_HELPER = re.compile(r"([A-Za-z][A-Za-z0-9+.-]*)::")
_SCHEME = re.compile(r"([A-Za-z][A-Za-z0-9+.-]*)://")
_KNOWN = "https://host/path, ssh://[user@]host/path or user@host:path"


def without_userinfo(url: str) -> str:
    """``url`` with its userinfo (``user:token@`` of a URL, ``user@`` of an scp-like address) replaced by ``***@``:
    what robocore prints of a URL it refuses, so that a token in it never reaches a terminal or a CI log."""
    scheme = re.match(r"[A-Za-z][A-Za-z0-9+.-]*://", url)
    start = scheme.end() if scheme else 0
    # the authority ends at the path (or a URL's query or fragment); its userinfo ends at its last "@", so that a
    # token holding "@", a space or a control character is hidden whole
    stops = ("/", "?", "#") if scheme else ("/",)
    ends = [found for found in (url.find(stop, start) for stop in stops) if found != -1]
    at = url.rfind("@", start, min(ends, default=len(url)))
    return url if at == -1 else f"{url[:start]}***{url[at:]}"


def gitops_url(value: str, allow: str | None = None) -> str:
    """``value`` if it is a git URL a GitOps controller may clone: robot.yaml's https, ssh and scp-like forms, and
    http only when ``allow`` is ``http`` (never git://, file:// or ext::, which the controller cannot or must not
    use); ValueError that never shows the URL's userinfo."""
    protocol = git_protocol(value)
    bare = without_userinfo(value)
    shown_url = shown(bare)
    if protocol in ("https", "http") and bare != value:
        # a user in an https URL is often a token (GitHub, GitLab take one there), and this URL is written into the
        # files export commits; the controllers take https credentials from a Secret of their own
        return _refuse(f"{shown_url} names a user: the URL goes into the exported files, which are committed; "
                       "give the controller its credentials in its own Secret (Argo CD's repository Secret, Fleet's "
                       "clientSecretName) and name no user here")
    if protocol in DEFAULT_PROTOCOLS or (protocol == "http" and allow == "http"):
        return value
    if protocol == "http":
        return _refuse(f"{shown_url} uses http://, which is neither encrypted nor authenticated; use https:// or "
                       "ssh://, or say allow_protocol: http in fleet.yaml's gitops")
    return _refuse(f"{shown_url} is a {protocol} URL; a GitOps controller clones {_KNOWN}")


def _refuse(message: str) -> str:
    raise ValueError(message)


def _why_not_a_url(url: str) -> str:
    what = f"must be a git URL ({_KNOWN})"
    seen = without_userinfo(url)
    if not url:
        return f"{what}, not empty"
    if url.startswith("-"):
        return f"{what}, not an option (got {shown(seen)})"
    if has_control(url):
        return f"{what} without control characters (got {shown(seen)})"
    if len(url) > 2048:
        return f"{what} of at most 2048 characters (got {len(url)} characters)"
    helper = _HELPER.match(url)
    if helper and helper.group(1) != "ext":
        return (f"{shown(seen)} asks git for the remote helper {helper.group(1)!r}, which runs a program on this "
                f"machine; robocore fetches {_KNOWN}")
    if not helper and any(ch.isspace() for ch in url):
        return f"{what} without spaces (got {shown(seen)})"
    scheme = _SCHEME.match(url)
    if scheme and scheme.group(1).lower() not in {"https", "ssh", "http", "git", "file"}:
        return f"{what}; the scheme {scheme.group(1)!r} is not one robocore fetches (got {shown(seen)})"
    if re.match(rf"[a-z]+://{_USER}:[^@/]*@", url):
        return f"must not hold a password (got {shown(url.split(':', 1)[0] + '://...')}); use ssh keys or a git " \
               "credential helper"
    return f"{what} (got {shown(seen)})"


def git_url(value: str) -> str:
    """``value`` if it is a git URL in one of robocore's forms (see :data:`URL_FORMS`)."""
    git_protocol(value)
    return value


def allowed_protocols(allow: str | None) -> tuple[str, ...]:
    """The git protocols an entry with ``allow_protocol: allow`` may use (for git's ``protocol.<name>.allow``)."""
    return (*DEFAULT_PROTOCOLS, allow) if allow and allow not in DEFAULT_PROTOCOLS else DEFAULT_PROTOCOLS


def protocol_problem(url: str, allow: str | None) -> str | None:
    """Why ``url`` may not be fetched with ``allow_protocol: allow`` (None when it may)."""
    protocol = git_protocol(url)
    seen = shown(without_userinfo(url))
    if protocol in DEFAULT_PROTOCOLS or protocol == allow:
        return None
    if protocol == "ext":
        return (f"{seen} is an ext:: URL, which runs a command on this machine; robocore fetches it only "
                "when this entry says allow_protocol: ext")
    if protocol == "file":
        return (f"{seen} is a local path or file:// URL (this machine's files); robocore fetches it only "
                "when this entry says allow_protocol: file")
    return (f"{seen} uses {protocol}://, which is neither encrypted nor authenticated; use https:// or "
            f"ssh://, or say allow_protocol: {protocol} in this entry")


# --- versions ---------------------------------------------------------------------------------------

#: A git ref name (``git check-ref-format`` with one level allowed, as for branches) or a commit id,
#: limited to letters, digits and ``. _ / + @ -``.
GIT_REF = (
    r"(?=[A-Za-z0-9._/+@-]{1,255}$)(?!-)(?!/)(?!.*//)(?!.*\.\.)(?!@$)(?!.*(?:^|/)\.)"
    r"(?!.*\.lock(?:/|$))(?!.*[/.]$)[A-Za-z0-9._/+@-]+"
)
_REF_CHARS = re.compile(r"[A-Za-z0-9._/+@-]*")


def git_ref_problem(value: str) -> str | None:
    """Why ``value`` is not a ref name or commit id robocore passes to git (None when it is)."""
    if not value:
        return "is empty"
    if value.startswith("-"):
        return "must not start with '-' (it would be an option)"
    if has_control(value):
        return "must not hold control characters"
    if not _REF_CHARS.fullmatch(value):
        bad = next(ch for ch in value if not _REF_CHARS.fullmatch(ch))
        return f"holds {bad!r}; versions may hold letters, digits and . _ / + @ - only"
    if len(value) > 255:
        return f"is too long ({len(value)} characters, at most 255)"
    parts = value.split("/")
    rules = [
        (value == "@", "cannot be '@' alone"),
        (value.startswith("/") or value.endswith("/") or "" in parts, "cannot start or end with '/' or hold '//'"),
        (".." in value, "cannot hold '..'"),
        (any(p.startswith(".") for p in parts), "no part may start with '.'"),
        (any(p.endswith(".lock") for p in parts), "no part may end with '.lock'"),
        (value.endswith("."), "cannot end with '.'"),
    ]
    for broken, why in rules:
        if broken:
            return why
    return None


def git_ref(value: str) -> str:
    """``value`` if it is a valid git ref name (branch, tag) or commit id."""
    problem = git_ref_problem(value)
    if problem is None and re.fullmatch(GIT_REF, value):
        return value
    raise ValueError(f"must be a branch, tag or commit id: {problem or 'not a git ref name'} (got {shown(value)})")


# --- checkout folders ------------------------------------------------------------------------------------

_SEGMENT = r"(?!\.\.?(?:/|$))(?!-)[A-Za-z0-9._+@-]+"
#: A relative folder under the workspace's ``src/``: no ``.``/``..`` parts, no leading ``-`` or ``/``.
CHECKOUT_FOLDER = rf"(?=.{{1,255}}$){_SEGMENT}(?:/{_SEGMENT})*"


def checkout_folder_problem(value: str) -> str | None:
    """Why ``value`` cannot be a checkout folder under ``src/`` (None when it can)."""
    if re.fullmatch(CHECKOUT_FOLDER, value):
        return None
    return (f"{shown(value)} must be a relative folder under src/ (no '..', '.', '//' or leading '-'; letters, "
            "digits and . _ + @ - in each part)")


def checkout_folder(value: str) -> str:
    """``value`` if it is a safe relative folder under ``src/``."""
    problem = checkout_folder_problem(value)
    if problem is not None:
        raise ValueError(problem)
    return value


def default_folder(url: str) -> str:
    """The checkout folder of ``url`` when none is given: its last path segment, without ``.git``."""
    tail = url.rstrip("/").rsplit("/", 1)[-1].rsplit(":", 1)[-1]
    return tail[:-4] if tail.endswith(".git") else tail or "repo"


GitUrl = Annotated[str, AfterValidator(git_url), pattern_field(
    GIT_URL, "Git URL: https://, ssh:// or user@host:path; http://, git://, file://, a local path or ext:: "
    "only with allow_protocol. No passwords.",
)]
GitRef = Annotated[str, AfterValidator(git_ref), pattern_field(
    GIT_REF, "Branch, tag or commit id (a git ref name: letters, digits and . _ / + @ -).",
)]
CheckoutFolder = Annotated[str, AfterValidator(checkout_folder), pattern_field(
    CHECKOUT_FOLDER, "Folder name under the workspace's src/ (default: from the URL).",
)]


#: The help of ``allow_protocol`` (robot.yaml and the JSON Schema).
ALLOW_PROTOCOL_HELP = (
    f"Fetch this URL although it is not {' or '.join(DEFAULT_PROTOCOLS)}: http and git (unencrypted, "
    "unauthenticated), file (a local path or file:// URL: this machine's files) or ext (ext:: runs a command on "
    "this machine; validate warns)."
)


def url_rules(schema: dict[str, Any], key: str) -> None:
    """Tie the URL form to ``allow_protocol`` in the JSON Schema, as validate does."""
    options: list[Any] = [{"properties": {key: {"pattern": schema_pattern(DEFAULT_GIT_URL)}}}]
    for protocol in OPT_IN_PROTOCOLS:
        pattern = schema_pattern(url_pattern(protocol))
        options.append({
            "properties": {"allow_protocol": {"const": protocol}, key: {"pattern": pattern}},
            "required": ["allow_protocol"],
        })
    schema["anyOf"] = options
