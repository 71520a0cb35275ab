"""robot.yaml text to Python values, with the line of every key, and nothing a file can use to hang,
exhaust or crash the reader.

A file over 1 MB is refused before parsing; nesting deeper than :data:`MAX_DEPTH` levels, aliases
that refer to themselves and alias bombs are refused while composing, each with one message.
PyYAML's safe loader builds the values; libyaml scans and parses when it is installed.
"""

from __future__ import annotations

import contextlib
import gc
import re
from collections.abc import Iterator, Sequence
from typing import Any

import yaml

from robocore.config.values import printable, shown
from robocore.errors import ConfigError, Problem
from robocore.files import ROBOT_FILE as ROBOT_FILE
from robocore.ui import plain_words

KeyPath = tuple[str | int, ...]

#: Largest robot.yaml read; a real one is a few kilobytes, and anything bigger is refused before parsing.
MAX_FILE_BYTES = 1_000_000
#: Deepest nesting of mappings and lists; robot.yaml itself needs 6.
MAX_DEPTH = 50
#: Longest message of one problem.
MAX_MESSAGE = 300


def _one_line(text: str, limit: int | None = None) -> str:
    """``text`` on one line, non-printable characters escaped, at most ``limit`` characters."""
    text = printable(" ".join(text.splitlines()).strip())
    if limit is not None and len(text) > limit:
        text = text[: limit - 3] + "..."
    return text


class LineMap:
    """Line numbers (1-based) of every key path in a YAML document."""

    def __init__(self) -> None:
        self.lines: dict[KeyPath, int] = {}
        self.duplicates: list[tuple[KeyPath, int]] = []

    def add(self, node: yaml.Node, path: KeyPath = ()) -> None:
        """Record ``node`` and its children under ``path``."""
        self.lines.setdefault(path, node.start_mark.line + 1)
        if isinstance(node, yaml.MappingNode):
            seen: set[str] = set()
            for key_node, value_node in node.value:
                key = key_node.value if isinstance(key_node, yaml.ScalarNode) else f"<{key_node.tag}>"
                child = (*path, key)
                if key in seen and key != "<<":
                    self.duplicates.append((child, key_node.start_mark.line + 1))
                seen.add(key)
                self.lines.setdefault(child, key_node.start_mark.line + 1)
                self.add_value(value_node, child)
        elif isinstance(node, yaml.SequenceNode):
            for index, item in enumerate(node.value):
                self.add(item, (*path, index))

    def add_value(self, node: yaml.Node, path: KeyPath) -> None:
        """Record the children of a mapping value without moving the key's own line."""
        if isinstance(node, (yaml.MappingNode, yaml.SequenceNode)):
            keep = self.lines[path]
            self.add(node, path)
            self.lines[path] = keep

    def line_of(self, path: Sequence[object]) -> int | None:
        """The line of ``path``, or of its nearest ancestor that is in the file."""
        probe: KeyPath = ()
        line = self.lines.get(())
        for part in path:
            candidates: list[str | int] = [part] if isinstance(part, (str, int)) and not isinstance(part, bool) else []
            candidates += [str(part), str(part).lower()]
            for candidate in candidates:
                if (*probe, candidate) in self.lines:
                    probe = (*probe, candidate)
                    line = self.lines[probe]
                    break
            else:
                break
        return line


def problem(file: str, line: int | None, path: str, message: str, *, severity: str = "error") -> Problem:
    """A :class:`Problem` whose text is one line of printable characters, its message at most
    :data:`MAX_MESSAGE` long."""
    return Problem(_one_line(file) or ROBOT_FILE, line, _one_line(path, MAX_MESSAGE),
                   _one_line(message, MAX_MESSAGE) or "invalid", severity=severity)


def _yaml_error(exc: yaml.YAMLError, file: str) -> ConfigError:
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    line = mark.line + 1 if mark is not None else None
    if isinstance(exc, yaml.reader.ReaderError):
        what = f"character {exc.character!r} is not allowed in YAML"
        line = None
    else:
        what = getattr(exc, "problem", None) or str(exc)
        context = getattr(exc, "context", None)
        if "maximum nesting depth" in what:  # PyYAML >= 6.0.3 limits flow nesting in its scanner
            return ConfigError([problem(file, line, "", f"YAML is nested more than {MAX_DEPTH} levels deep")])
        if context:
            what = f"{context}, {what}"
    label = "YAML error" if isinstance(exc, yaml.constructor.ConstructorError) else "YAML syntax error"
    return ConfigError([problem(file, line, "", f"{label}: {what}")])


#: Most values a robot.yaml may expand to (aliases included); far above any real robot.
MAX_VALUES = 200_000
#: Most bytes of text (keys and scalars) a robot.yaml may expand to, aliases expanded: twice the largest file, so
#: that what is built from it (Dockerfiles, compose files, JSON) stays as bounded as the file itself.
MAX_EXPANDED_BYTES = 2 * MAX_FILE_BYTES


def _check_size(root: yaml.Node, file: str) -> None:
    """Refuse recursive aliases and alias bombs before anything walks the document: the document is measured by
    what it expands to (values and bytes of text, every alias counted in full), in one pass over its nodes."""
    sizes: dict[int, tuple[int, int]] = {}
    active: set[int] = set()

    def size(node: yaml.Node) -> tuple[int, int]:
        key = id(node)
        if key in sizes:
            return sizes[key]
        if key in active:
            line = node.start_mark.line + 1
            raise ConfigError([problem(file, line, "", "an alias refers to itself (recursive anchor)")])
        active.add(key)
        values, text = 1, 0
        if isinstance(node, yaml.ScalarNode):
            text = len(node.value)
        children: list[yaml.Node] = []
        if isinstance(node, yaml.MappingNode):
            children = [item for pair in node.value for item in pair]
        elif isinstance(node, yaml.SequenceNode):
            children = list(node.value)
        for child in children:
            more, longer = size(child)
            values += more
            text += longer
        active.discard(key)
        if values > MAX_VALUES:
            what = f"document expands to more than {MAX_VALUES} values (aliases?)"
            raise ConfigError([problem(file, None, "", what)])
        if text > MAX_EXPANDED_BYTES:
            what = (f"document expands to more than {MAX_EXPANDED_BYTES:,} bytes of text with its aliases expanded "
                    "(an alias repeated too often?)")
            raise ConfigError([problem(file, None, "", what)])
        sizes[key] = values, text
        return values, text

    size(root)


_SURROGATE = re.compile("[\ud800-\udfff]")


def _refuse_surrogates(root: yaml.Node, file: str) -> None:
    """Refuse a string holding a lone surrogate (``"\\udc80"``): no UTF-8 file, environment or container can carry
    it, so a compose file or an image built from it would fail later, far from its line."""
    stack: list[tuple[yaml.Node, KeyPath]] = [(root, ())]
    seen: set[int] = set()
    while stack:
        node, path = stack.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        if isinstance(node, yaml.ScalarNode) and _SURROGATE.search(node.value):

            where = "".join(f"[{part}]" if isinstance(part, int) else f".{part}" for part in path).lstrip(".")
            raise ConfigError([problem(file, node.start_mark.line + 1, where, f"{shown(node.value)} holds a lone "
                                       "surrogate, which no UTF-8 file, environment or container can carry")])
        if isinstance(node, yaml.MappingNode):
            stack += [(item, (*path, key.value if isinstance(key, yaml.ScalarNode) else "?"))
                      for key, value in node.value for item in (key, value)]
        elif isinstance(node, yaml.SequenceNode):
            stack += [(item, (*path, index)) for index, item in enumerate(node.value)]


#: Integers YAML 1.1 reads in a way nobody means in robot.yaml: octal (``022`` is 18), hexadecimal, binary,
#: base 60 (``1:30`` is 90) and digits grouped with ``_``.
_SURPRISING_INT = re.compile(r"[-+]?(?:0[0-7_]+|0[xob].*|.*:.*|.*_.*)")


def _construct_int(loader: Any, node: yaml.ScalarNode) -> Any:
    """PyYAML's integer, but a plain scalar YAML 1.1 reads as octal, hex, binary or base 60 is refused."""
    if not node.style and _SURPRISING_INT.fullmatch(node.value):  # plain: None (PyYAML) or "" (libyaml)
        value = yaml.constructor.SafeConstructor.construct_yaml_int(loader, node)
        what = (f"{shown(node.value)} is read by YAML 1.1 as the number {value} (octal, hexadecimal, binary, base 60 "
                f"or grouped digits); write {value} if that is meant, or quote it if text is")
        raise ConfigError([problem(loader.file, node.start_mark.line + 1, "", what)])
    return yaml.constructor.SafeConstructor.construct_yaml_int(loader, node)


class _DepthLimit(yaml.composer.Composer):
    """PyYAML's composer with a nesting limit: composing nodes is recursive, and a deep document
    would otherwise end in RecursionError (or worse) instead of a message. Its integers refuse
    YAML 1.1's surprises (:data:`_SURPRISING_INT`)."""

    file = ROBOT_FILE
    depth = 0
    yaml_constructors = {**yaml.SafeLoader.yaml_constructors, "tag:yaml.org,2002:int": _construct_int}

    def compose_node(self, parent: yaml.Node | None, index: int) -> yaml.Node | None:
        """Compose one node, refusing documents nested more than :data:`MAX_DEPTH` levels."""
        self.depth += 1
        try:
            if self.depth > MAX_DEPTH:
                line = self.peek_event().start_mark.line + 1  # type: ignore[attr-defined]
                raise ConfigError([problem(self.file, line, "", f"YAML is nested more than {MAX_DEPTH} levels deep")])
            return super().compose_node(parent, index)
        finally:
            self.depth -= 1


class _Loader(_DepthLimit, yaml.SafeLoader):
    """The safe loader, all in Python: the reference for error messages."""

    def __init__(self, stream: str, file: str) -> None:
        yaml.SafeLoader.__init__(self, stream)
        self.file = file


def _fast_loader() -> Any:
    """A loader class whose scanning and parsing are libyaml's (7x faster on large files) and whose composing
    stays in Python (with the depth limit); None without libyaml."""
    base: Any = getattr(yaml, "CSafeLoader", None)
    if base is None:
        return None

    class _CLoader(_DepthLimit, base):  # type: ignore[misc]
        def __init__(self, stream: str, file: str) -> None:
            base.__init__(self, stream)
            yaml.composer.Composer.__init__(self)
            self.file = file

    return _CLoader


_FastLoader: Any = _fast_loader()


def _native_loader() -> Any:
    """A loader class that is libyaml's all through composing (its composer is compiled: 2x faster than PyYAML's
    over libyaml's events on a 10,000-robot fleet.yaml), with robocore's integers; None without libyaml. It has no
    depth limit of its own (libyaml stops at 1000 levels): :func:`_deeper_than` checks the document it composed."""
    base: Any = getattr(yaml, "CSafeLoader", None)
    if base is None:
        return None

    class _Native(base):  # type: ignore[misc]
        yaml_constructors = _DepthLimit.yaml_constructors

        def __init__(self, stream: str, file: str) -> None:
            base.__init__(self, stream)
            self.file = file

    return _Native


#: The loader :func:`_compose` tries first (None without libyaml).
NativeLoader: Any = _native_loader()


def _deeper_than(root: yaml.Node, limit: int) -> bool:
    """True when a node of ``root`` sits more than ``limit`` levels deep as the text nests it (the root is level 1),
    as :class:`_DepthLimit` counts: an alias counts as one node where it stands. Composed aliases are the anchored
    node itself, met again: the first meeting, in document order, is the anchor's own place."""
    seen: set[int] = set()
    stack: list[tuple[yaml.Node, int]] = [(root, 1)]
    while stack:
        node, level = stack.pop()
        if level > limit:
            return True
        if id(node) in seen:
            continue
        seen.add(id(node))
        if isinstance(node, yaml.MappingNode):
            stack.extend((item, level + 1) for pair in reversed(node.value) for item in reversed(pair))
        elif isinstance(node, yaml.SequenceNode):
            stack.extend((item, level + 1) for item in reversed(node.value))
    return False


#: Above this size, a syntax error libyaml found is reported as libyaml words it (reading the file again
#: with PyYAML, for its clearer message, would take seconds).
REREAD_LIMIT = 100_000


def _compose(text: str, file: str) -> tuple[Any, yaml.Node | None]:
    """A loader and the document's root node. libyaml's parser and composer when it is there; a document they find
    wrong, or nested deeper than :data:`MAX_DEPTH`, is composed again as before (libyaml's parser, PyYAML's composer
    with the depth limit, then PyYAML's own parser for its clearer messages): its refusal is the same words, the
    same line."""
    if NativeLoader is not None:
        native = NativeLoader(text, file)
        try:
            root = native.get_single_node()
            if root is None or not _deeper_than(root, MAX_DEPTH):
                return native, root
        except Exception:  # said again, in the usual words, below
            pass
        native.dispose()
    if _FastLoader is not None:
        loader = _FastLoader(text, file)
        try:
            return loader, loader.get_single_node()
        except ConfigError:
            loader.dispose()
            raise
        except yaml.MarkedYAMLError:
            loader.dispose()
            if len(text) > REREAD_LIMIT:
                raise
        except Exception:
            loader.dispose()
    loader = _Loader(text, file)
    try:
        return loader, loader.get_single_node()
    except BaseException:
        loader.dispose()
        raise


def too_big(size: int, file: str, kind: str = ROBOT_FILE) -> ConfigError:
    """The one-line refusal of a file of ``size`` bytes (over :data:`MAX_FILE_BYTES`); ``kind`` names the file
    (robot.yaml, fleet.yaml)."""
    what = f"file is larger than 1 MB ({size:,} bytes); a {kind} is a few kilobytes"
    return ConfigError([problem(file, None, "", what)])


def read_yaml(text: str, file: str, *, kind: str = ROBOT_FILE,
              schema_hint: str = "robocore schema") -> tuple[Any, LineMap]:
    """Compose and load ``text``; raise a one-problem ConfigError when it is not YAML. ``kind`` names the file
    (robot.yaml, fleet.yaml) and ``schema_hint`` the command that prints its keys, for messages."""
    if len(text) > MAX_FILE_BYTES or len(text.encode("utf-8", errors="replace")) > MAX_FILE_BYTES:
        raise too_big(len(text.encode("utf-8", errors="replace")), file, kind)
    if "\x00" in text:
        raise ConfigError([problem(file, None, "", "not a text file (contains NUL bytes)")])
    with _collector_paused():
        return _read_yaml(text, file, schema_hint)


@contextlib.contextmanager
def _collector_paused() -> Iterator[None]:
    """Python's cyclic garbage collector paused while a file is read: composing and building a large document makes
    objects that all stay alive (a fleet.yaml of 10,000 robots, 200,000 of them), which the collector would walk
    again and again to find nothing, half of the reading's time. What one reading can leave in reference cycles
    is bounded as the file is (:data:`MAX_FILE_BYTES`, :data:`MAX_VALUES`); the collector runs on afterwards."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def _read_yaml(text: str, file: str, schema_hint: str) -> tuple[Any, LineMap]:
    try:
        loader, node = _compose(text, file)
        try:
            if node is None:
                raise ConfigError([problem(file, None, "", f"file is empty; see '{schema_hint}' for its keys")])
            _check_size(node, file)
            if "\\u" in text or "\\U" in text:  # only an escape can make a lone surrogate: UTF-8 text holds none
                _refuse_surrogates(node, file)
            lines = LineMap()
            lines.add(node)
            data = _construct(loader, node, file)
        finally:
            loader.dispose()
    except yaml.YAMLError as exc:
        raise _yaml_error(exc, file) from None
    except RecursionError:
        raise ConfigError([problem(file, None, "", "YAML is nested too deeply")]) from None
    return data, lines


def _construct(loader: Any, node: yaml.Node, file: str) -> Any:
    """Build Python values from ``node``.

    PyYAML's constructors raise assorted exceptions on malformed tagged values (an empty
    ``!!timestamp`` raises AttributeError, a bad date ValueError); every one of them is a
    problem of the file, not of robocore.
    """
    try:
        return loader.construct_document(node)
    except (yaml.YAMLError, RecursionError, ConfigError):
        raise
    except Exception as exc:
        culprit = _culprit(node)
        if culprit is None:
            why_not = plain_words(str(exc))
            raise ConfigError([problem(file, None, "", f"YAML value could not be read: {why_not}")]) from None
        bad, why = culprit
        tag = bad.tag.rsplit(":", 1)[-1]
        reason = str(why) if isinstance(why, (ValueError, yaml.YAMLError)) else "malformed value"
        reason = plain_words(reason)  # Python's digit limit, not a setting the user can change here
        message = f"YAML value {shown(bad.value)} could not be read as {tag}: {reason}"
        raise ConfigError([problem(file, bad.start_mark.line + 1, "", message)]) from None


def _culprit(root: yaml.Node) -> tuple[yaml.ScalarNode, Exception] | None:
    """The first scalar that cannot be constructed on its own, with its exception."""
    stack = [root]
    seen: set[int] = set()
    while stack:
        node = stack.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        if isinstance(node, yaml.ScalarNode):
            probe = yaml.SafeLoader("")
            try:
                probe.construct_object(node)
            except Exception as exc:
                return node, exc
            finally:
                probe.dispose()
        elif isinstance(node, yaml.MappingNode):
            stack.extend(item for pair in reversed(node.value) for item in reversed(pair))
        elif isinstance(node, yaml.SequenceNode):
            stack.extend(reversed(node.value))
    return None
