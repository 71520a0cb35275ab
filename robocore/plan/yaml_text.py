"""Block YAML text of plain documents, written directly: the very text PyYAML's safe dumper writes, faster.

PyYAML's emitter runs every scalar through a Python representer and resolver (the C emitter too): for a compose
file of 10,000 services that is most of the time ``stage`` spends writing it (bench/compose_scale.py). The
documents robocore writes are simple (nested dicts and lists of strings, ints and booleans), and almost every
string in them is a name, a path or a hash that PyYAML writes as it is. Those are written here, and empty lists and
mappings (``[]``, ``{}``); any entry that holds something else (a string that needs quoting beyond ``'0'``-style, a
float, a list in a list, ...) is handed to PyYAML itself, at its depth, so the text stays byte for byte what PyYAML
writes (tests/test_yaml_text.py compares the two on hostile values).
"""

from __future__ import annotations

import functools
import re
from collections.abc import Mapping
from typing import Any

import yaml

#: libyaml's emitter where PyYAML was built with it (on what robocore writes, the same text as the pure-Python one),
#: else PyYAML's own: what writes the entries this module leaves to PyYAML.
DUMPER: type[yaml.SafeDumper] = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
#: The line width the text is written for (PyYAML breaks long plain and quoted strings at spaces past it).
WIDTH = 120

# Strings PyYAML writes unquoted (when they read back as strings) or in single quotes (when they would read back as
# something else, like '0' or 'yes'): printable ASCII without the characters that start or end YAML syntax.
# Spaces are allowed inside (the caller checks that the line cannot be broken); ': ' is ruled out by the caller.
_SIMPLE = re.compile(r"[A-Za-z0-9_./-](?:[A-Za-z0-9_./:@+=,%~ -]*[A-Za-z0-9_./@+=,%~-])?\Z")
_RESOLVER = yaml.resolver.Resolver()
_STR_TAG = "tag:yaml.org,2002:str"
_FIRST_CHARS = frozenset(k for k in _RESOLVER.yaml_implicit_resolvers if k)  # where a string may read as non-str
_MAX_SIMPLE_KEY = 128  # PyYAML writes longer keys as '? key'


class _Unwritten(Exception):
    """A value this module leaves to PyYAML."""


def dump(document: Mapping[str, Any], *, width: int = WIDTH, allow_unicode: bool = False) -> str:
    """``yaml.dump(document, Dumper=DUMPER, sort_keys=False, default_flow_style=False, width=width,
    allow_unicode=allow_unicode)``, faster.

    The same text, written directly where the values are simple (see the module's docstring); what is not
    simple goes through PyYAML entry by entry, so a hostile value costs only its own entry's time. The Kubernetes
    export writes with a width no line reaches and ``allow_unicode`` (its non-ASCII strings go to PyYAML)."""
    if not isinstance(document, dict) or not document:
        return _pyyaml(document, width, allow_unicode)
    writer = _Writer(width, allow_unicode)
    writer.mapping(document, "", top=True)
    return "".join(writer.out)


def _pyyaml(value: Any, width: int = WIDTH, allow_unicode: bool = False) -> str:
    unicode = allow_unicode or None  # PyYAML's default
    try:
        return yaml.dump(value, Dumper=DUMPER, sort_keys=False, default_flow_style=False, width=width,
                         allow_unicode=unicode)
    except UnicodeEncodeError:  # a lone surrogate, which libyaml cannot encode: PyYAML's own emitter escapes it
        return yaml.dump(value, Dumper=yaml.SafeDumper, sort_keys=False, default_flow_style=False, width=width,
                         allow_unicode=unicode)


def _string(value: str, column: int, *, key: bool, width: int = WIDTH) -> str:
    """The text of a string that starts at ``column``; raises :class:`_Unwritten` when PyYAML must write it."""
    if not _SIMPLE.match(value) or value.startswith(("---", "...", "- ")) or value == "-" or ": " in value:
        raise _Unwritten
    if " " in value and (key or column + len(value) + 2 > width):  # PyYAML may break the line at a space
        raise _Unwritten
    if key and len(value) >= _MAX_SIMPLE_KEY:
        raise _Unwritten
    if value[0] in _FIRST_CHARS and not _reads_as_string(value):
        return f"'{value}'"  # would read back as a number, a boolean, null...: quoted, as PyYAML does
    return value


@functools.lru_cache(maxsize=4096)  # a document repeats its '0's and 'true's
def _reads_as_string(value: str) -> bool:
    tag: str = _RESOLVER.resolve(yaml.ScalarNode, value, (True, False))  # type: ignore[no-untyped-call]
    return tag == _STR_TAG


class _Writer:
    """The lines of one document; the text of each string without a space is worked out once."""

    def __init__(self, width: int = WIDTH, allow_unicode: bool = False) -> None:
        self.width, self.allow_unicode = width, allow_unicode
        self.out: list[str] = []
        self.keys: dict[str, str] = {}
        self.values: dict[str, str] = {}

    def key(self, key: Any, column: int) -> str:
        if type(key) is not str:
            raise _Unwritten
        text = self.keys.get(key)
        if text is None:
            text = self.keys[key] = _string(key, column, key=True, width=self.width)
        return text

    def value(self, value: Any, column: int) -> str:
        if type(value) is str:
            text = self.values.get(value)
            if text is None:
                text = _string(value, column, key=False, width=self.width)
                if " " not in value:  # its text does not depend on its column
                    self.values[value] = text
            return text
        if value is True:
            return "true"
        if value is False:
            return "false"
        if value is None:
            return "null"
        if type(value) is int:
            return str(value)
        raise _Unwritten

    def mapping(self, mapping: dict[Any, Any], indent: str, *, top: bool, first: str | None = None) -> None:
        """Append a block mapping at ``indent`` (its first line starting with ``first`` instead, in a sequence).

        ``top``: the mapping and all its parents are mappings, so one entry can be left to PyYAML on its own."""
        out = self.out
        for key, value in mapping.items():
            lead = indent if first is None else first
            first = None
            mark = len(out)
            try:
                self.entry(key, value, lead, indent, top=top)
            except _Unwritten:
                if not top:
                    raise
                del out[mark:]
                out.append(_pyyaml_entry(key, value, len(indent) // 2, self.width, self.allow_unicode))

    def entry(self, key: Any, value: Any, lead: str, indent: str, *, top: bool) -> None:
        text = self.key(key, len(indent))
        if isinstance(value, dict):
            if not value:  # an empty collection is written in flow style, as PyYAML writes it
                self.out.append(f"{lead}{text}: {{}}\n")
                return
            self.out.append(f"{lead}{text}:\n")
            self.mapping(value, indent + "  ", top=top)
        elif isinstance(value, list):
            if not value:
                self.out.append(f"{lead}{text}: []\n")
                return
            self.out.append(f"{lead}{text}:\n")
            self.sequence(value, indent)  # in a mapping, PyYAML does not indent a sequence
        else:
            self.out.append(f"{lead}{text}: {self.value(value, len(indent) + len(text) + 2)}\n")

    def sequence(self, items: list[Any], indent: str) -> None:
        for item in items:
            if isinstance(item, dict) and item:
                self.mapping(item, indent + "  ", top=False, first=indent + "- ")
            elif isinstance(item, (dict, list)):
                if item:  # a list in a list
                    raise _Unwritten
                self.out.append(f"{indent}- {'{}' if isinstance(item, dict) else '[]'}\n")
            else:
                self.out.append(f"{indent}- {self.value(item, len(indent) + 2)}\n")


def _pyyaml_entry(key: Any, value: Any, depth: int, width: int = WIDTH, allow_unicode: bool = False) -> str:
    """PyYAML's text of one mapping entry at ``depth`` (nested mappings above it): the same lines as in the whole
    document, since a block mapping's entries are written one after another at their indent."""
    nested: Any = {key: value}
    for _ in range(depth):
        nested = {"x": nested}
    text = _pyyaml(nested, width, allow_unicode)
    for _ in range(depth):
        text = text.split("\n", 1)[1]
    return text
