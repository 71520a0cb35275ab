"""Console output: one rich console on stderr for progress and messages, and the escaping of what is printed.

Values printed by robocore come from robot.yaml, from the command line, from hosts and from
containers; any of them may carry terminal control sequences (an OSC sequence in a host
address retitles the terminal, a clear-screen hides what came before). :func:`clean` turns every
control character into a visible escape (``\\x1b``); it is applied at the print edges: the rich
consoles below escape every string they render (table cells and titles included), and the
plain ``print`` edges (error lines, dry-run plans, log lines) call it themselves.
"""

from __future__ import annotations

import functools
import re
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rich.console import Console

#: C0 controls except tab and newline, DEL, C1 controls, and the Unicode bidirectional overrides
#: and isolates (they reorder what the reader sees).
_CONTROL = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u202a-\u202e\u2066-\u2069]")
#: A Select Graphic Rendition sequence (colours, bold): the only escape sequence :func:`clean` may keep.
_SGR = re.compile(r"\x1b\[[0-9;:]{0,64}m")
_RESET = "\x1b[0m"


def _escape_char(match: re.Match[str]) -> str:
    code = ord(match.group())
    return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}"


def without_sgr(text: str) -> str:
    """``text`` without its colour sequences (``ESC [ ... m``): Docker's classic builder puts one before each
    chunk of a step's stderr, and a line read for its words must not carry it."""
    return _SGR.sub("", text)


def clean(text: str, *, keep_sgr: bool = False) -> str:
    """``text`` with every control character written as a visible escape (ESC as ``\\x1b``, a carriage
    return as ``\\x0d``, a bidirectional override as ``\\u202e``); tabs and newlines are kept.

    ``keep_sgr`` keeps colour sequences (``ESC [ ... m``), which container logs legitimately carry,
    and ends a line that used one with a reset so that colour does not leak into the next line;
    every other sequence (titles, cursor moves, screen clears) is still escaped.
    """
    if not _CONTROL.search(text):
        return text
    if not keep_sgr:
        return _CONTROL.sub(_escape_char, text)
    parts: list[str] = []
    last = 0
    for match in _SGR.finditer(text):
        parts.append(_CONTROL.sub(_escape_char, text[last:match.start()]))
        parts.append(match.group())
        last = match.end()
    parts.append(_CONTROL.sub(_escape_char, text[last:]))
    out = "".join(parts)
    return out + _RESET if last else out


#: Longest rendering of a user's value inside a message (:func:`shown`).
MAX_SHOWN = 60
#: Longest run of a value that reaches an error or warning line through any other way (:func:`bounded`), and the
#: longest such line: a 120,000-character option or robot.yaml value never comes back whole.
MAX_ECHO = 200
MAX_LINE = 1000
_QUOTED = re.compile(r"'(?:[^'\\\n]|\\.)*'|\"(?:[^\"\\\n]|\\.)*\"")
_LONG_WORD = re.compile(rf"\S{{{MAX_ECHO + 4},}}")  # longer than what a cut quoted value leaves


def shown(value: object, limit: int = MAX_SHOWN) -> str:
    """A short one-line ``repr`` of a user's value, at most about ``limit`` characters: a longer one is cut and
    says its length (``'xxxx...' (120000 characters)``)."""
    text = repr(value)
    if len(text) <= limit:
        return text
    size = len(value) if isinstance(value, (str, bytes, list, tuple, dict)) else len(text)
    return f"{text[: max(limit - 3, 1)]}... ({size:,} characters)"


def _cut(text: str, keep: int, size: int) -> str:
    return f"{text[:keep]}... ({size:,} characters)"


def bounded(text: str) -> str:
    """``text`` (an error or warning, one or more lines) with every quoted value and every word longer than
    :data:`MAX_ECHO` cut, saying its length, and every line cut at :data:`MAX_LINE`: the one rule for echoed
    values at the edges where messages are printed, whatever built the message."""
    if len(text) <= MAX_ECHO:
        return text
    text = _QUOTED.sub(lambda m: m.group() if len(m.group()) <= MAX_ECHO + 2 else
                       _cut(m.group(), MAX_ECHO, len(m.group()) - 2), text)
    text = _LONG_WORD.sub(lambda m: _cut(m.group(), MAX_ECHO, len(m.group())), text)
    return "\n".join(line if len(line) <= MAX_LINE else _cut(line, MAX_LINE, len(line))
                     for line in text.split("\n"))


_DIGITS = re.compile(r"value has (\d+) digits")
_NOT_INT = re.compile(r"invalid literal for int\(\) with base \d+: (.*)", re.S)


def plain_words(reason: str) -> str:
    """Python's words for a number it cannot convert, in a user's words: no ``sys.set_int_max_str_digits()``
    (a setting of the Python process, not of robocore), no ``int() with base 10``. Other text is returned as is."""
    digits = _DIGITS.search(reason)
    if digits and "integer string conversion" in reason:
        return f"a number of {digits.group(1)} digits is too large"
    literal = _NOT_INT.match(reason)
    if literal:
        return f"not a whole number: {literal.group(1)}"
    return reason


def _make(**kwargs: Any) -> Console:
    from rich.console import Console
    from rich.text import Text

    class CleanConsole(Console):
        """A rich console that escapes control characters in every string it renders."""

        def render_str(self, text: str, **options: Any) -> Text:
            return super().render_str(clean(text), **options)

    return CleanConsole(highlight=False, soft_wrap=True, **kwargs)  # lines are never cut: logs and CI grep them


@functools.cache
def console() -> Console:
    """The console for human output (stderr, so stdout stays clean for --json)."""
    return _make(stderr=True)


@functools.cache
def stdout() -> Console:
    """The console for results meant for stdout (tables, JSON)."""
    return _make()


def make_console(**kwargs: Any) -> Console:
    """Another console with the same escaping (e.g. a fixed width for logs and CI)."""
    return _make(**kwargs)


def human_size(n: int) -> str:
    """A byte count for people: ``512 B``, ``1.5 KB``, ``3.2 MB``, ``1.1 GB`` (powers of 1024)."""
    size = float(n)
    for unit in ("B", "KB", "MB"):
        if size < 1024:
            return f"{size:.0f} {unit}" if unit == "B" else f"{size:.1f} {unit}"
        size /= 1024
    return f"{size:.1f} GB"
