"""Hints in messages: lists of known names and "did you mean" suggestions, cheap at any size."""

from __future__ import annotations

import difflib
from collections.abc import Iterable

from robocore.config.values import shown

#: Names listed in a "known: ..." hint; a longer list ends with how many there are.
MAX_LISTED = 10
#: Near-miss suggestions made per check run: each one compares a name with every known name.
MAX_SUGGESTIONS = 20


def known_list(names: Iterable[str], *, limit: int = MAX_LISTED) -> str:
    """``a, b, c`` or ``none``; past ``limit`` names, ``a, b, ... (N in all)``."""
    listed = [name if name.isprintable() else shown(name) for name in names]
    if len(listed) > limit:
        return ", ".join(listed[:limit]) + f", ... ({len(listed)} in all)"
    return ", ".join(listed) or "none"


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    """`` did you mean 'x'?`` for a near miss, else an empty string."""
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else ""


class Unknown:
    """Messages for references to undefined names (``runs_on: rpi6``), cheap for any number of them.

    The list of known names is rendered once, and only the first :data:`MAX_SUGGESTIONS` distinct
    unknown names get a "did you mean" (each costs a comparison with every known name).
    """

    def __init__(self, kind: str, known: Iterable[str]) -> None:
        self.kind = kind
        self.known = list(dict.fromkeys(known))
        self.names = set(self.known)
        self.listed = known_list(self.known)
        self.messages: dict[str, str] = {}

    def __contains__(self, name: object) -> bool:
        return name in self.names

    def message(self, name: str) -> str:
        """The message for the undefined ``name``."""
        if name not in self.messages:
            hint = ""
            if len(self.known) > 1 and len(self.messages) < MAX_SUGGESTIONS:
                hint = did_you_mean(name, self.known)
            self.messages[name] = f"unknown {self.kind} {name!r} (known: {self.listed}){hint}"
        return self.messages[name]


def unknown(kind: str, name: str, known: list[str]) -> str:
    """The message for a reference to something that is not defined."""
    return Unknown(kind, known).message(name)
