"""Reading text that anybody may have written: camera files, targets, batch manifests (issue 33).

Every reader of a user's file goes through here, so that no file can crash, hang or exhaust the
process, whatever it holds; what it cannot read is an InputError of one line naming the file:

- :func:`read_text`: the size is checked before anything is read (a 1 GB sparse file is refused
  from its inode) and at most ``max_bytes + 1`` bytes are ever read (a FIFO or /dev/zero too).
- :func:`load_yaml`: PyYAML's safe loader with a nesting limit (checked while the document is
  composed, before Python's recursion limit or the C stack could be reached), integers of at most
  MAX_INT_DIGITS digits, and aliases either refused (camera and target files: no real one uses
  them) or bounded by the size of the document they expand to (manifests: "billion laughs" is
  refused at the first node over the budget, not after minutes).
- :func:`load_json`: the same limits for JSON.
- :func:`load_python_literal`: a Python literal (mrcal's .cameramodel) by ast.literal_eval, with
  the same limits.
- :func:`check_nesting`: a scan of brackets, indentation, sequence dashes and XML tags for the
  parsers we cannot limit from outside (OpenCV's FileStorage segfaults past ~10^5 levels).
- :func:`one_line`: a message with control characters shown as escapes (a file name may hold a
  newline; the message must stay one line).
"""
from __future__ import annotations

import ast
import json
import os
import re
import stat
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..errors import InputError

__all__ = ["MAX_NESTING", "MAX_INT_DIGITS", "MAX_YAML_NODES", "YAML_MAX_BYTES", "read_text", "load_yaml", "load_json",
           "load_python_literal", "check_nesting", "nesting_depth", "one_line", "shown"]

# Real camera, target and manifest files nest fewer than 10 levels; 64 leaves room and stays far
# from Python's recursion limit (1000) and from OpenCV's stack.
MAX_NESTING = 64
# The longest integer a file may spell: real ones have < 20 digits; Python refuses > 4300 with a
# ValueError of its own, and converting long ones is quadratic.
MAX_INT_DIGITS = 100
# Nodes a YAML document may expand to once its aliases are followed (a manifest of 10 000 jobs of
# 20 fields is 4*10^5): the bound on "billion laughs".
MAX_YAML_NODES = 2_000_000
# PyYAML's safe loader is pure Python (the C one cannot be limited from outside): a few hundred kB a
# second, and ~80 bytes of memory per byte read. Camera and target files in YAML are a few kB.
YAML_MAX_BYTES = 1 << 20


def shown(path) -> str:
    """A path for a one-line message: control characters (a newline in a file name) as escapes."""
    return one_line(str(path))


def one_line(text: str) -> str:
    """`text` with every non-printable character (newline, tab, NUL...) written as its escape."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def _format_bytes(count: int) -> str:
    return f"{count / 2 ** 20:.1f} MiB" if count >= 2 ** 20 else f"{count} bytes"


def read_bytes(path, max_bytes: int, what: str = "file") -> bytes:
    """The bytes of `path`; InputError when it is not a readable file or holds more than
    `max_bytes` (refused from its size before reading; never more than max_bytes + 1 read)."""
    path = Path(path)
    try:
        # O_NONBLOCK: a FIFO must not hang the open; regular files ignore it
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError as error:
        reason = "not found" if isinstance(error, FileNotFoundError) else (error.strerror or str(error))
        raise InputError(f"{what} {shown(path)}: {reason}") from None
    try:
        info = os.fstat(fd)
        if stat.S_ISDIR(info.st_mode):
            raise InputError(f"{what} {shown(path)}: is a folder, not a file")
        if stat.S_ISREG(info.st_mode) and info.st_size > max_bytes:
            raise InputError(f"{what} {shown(path)}: {_format_bytes(info.st_size)}, more than the "
                             f"{_format_bytes(max_bytes)} such a file can be")
        if not stat.S_ISREG(info.st_mode):
            os.set_blocking(fd, True)
        chunks, total = [], 0
        while total <= max_bytes:
            chunk = os.read(fd, min(1 << 20, max_bytes + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
    except OSError as error:
        raise InputError(f"{what} {shown(path)}: cannot read it ({error.strerror or error})") from None
    finally:
        os.close(fd)
    if total > max_bytes:
        raise InputError(f"{what} {shown(path)}: more than the {_format_bytes(max_bytes)} such a file can be")
    return b"".join(chunks)


def read_text(path, max_bytes: int, what: str = "file", encoding: str = "utf-8", errors: str = "replace") -> str:
    """:func:`read_bytes` decoded (undecodable bytes replaced by default: the parsers then say
    what is wrong, naming the field)."""
    data = read_bytes(path, max_bytes, what)
    try:
        return data.decode(encoding, errors)
    except UnicodeDecodeError as error:
        name = "UTF-8" if encoding.lower().replace("_", "-").startswith("utf-8") else encoding
        raise InputError(f"{shown(path)}: not {name} text (byte {error.start})") from None


# -- nesting scan (for parsers that cannot be limited from outside) -----------------------------------

_QUOTED = re.compile(r'"(?:[^"\\\n]|\\.)*"|\'[^\'\n]*\'')
_XML_SKIP = re.compile(r"<!--.*?-->|<!\[CDATA\[.*?\]\]>|<\?.*?\?>|<![^>]*>", re.S)
_XML_TAG = re.compile(r"<(/?)[^<>]*?(/?)>")
_LONG_INTEGER = re.compile(r"(?<![\w.])\d[\d_]{" + str(MAX_INT_DIGITS) + r",}(?![\w.])")
_LINE_START = re.compile(r"^([ \t]*)((?:[-?:][ \t]+)*)", re.M)
_BRACKET_VALUE = np.zeros(256, dtype=np.int8)
_BRACKET_VALUE[[ord("["), ord("{"), ord("(")]] = 1
_BRACKET_VALUE[[ord("]"), ord("}"), ord(")")]] = -1


def _max_rise(steps: np.ndarray) -> int:
    """The deepest nesting of +1/-1 steps, counted from the lowest point before it (so that a
    stray closing bracket cannot hide the openings after it)."""
    if steps.size == 0:
        return 0
    level = np.cumsum(steps, dtype=np.int64)
    floor = np.minimum.accumulate(np.minimum(level, 0))
    return int(np.max(level - floor))


def _flow_depth(text: str) -> int:
    """Brackets outside quoted strings (JSON, YAML flow, Python literals)."""
    if sum(text.count(c) for c in "[{(") <= MAX_NESTING:
        return min(sum(text.count(c) for c in "[{("), MAX_NESTING)
    bare = _QUOTED.sub('""', text)
    data = np.frombuffer(bare.encode("utf-8", "replace"), dtype=np.uint8)
    return _max_rise(_BRACKET_VALUE[data])


def _block_depth(text: str) -> int:
    """YAML block nesting: the stack of indentations plus the `- ` / `? ` indicators that open a
    collection on the same line (`- - - x` is three sequences deep)."""
    starts = [(len(m.group(1).expandtabs(1)), len(m.group(2).split())) for m in _LINE_START.finditer(text)]
    if not starts:
        return 0
    deepest_inline = max(d for _, d in starts)
    widths = {w for w, _ in starts}
    if len(widths) + deepest_inline <= MAX_NESTING:
        return len(widths) + deepest_inline
    stack: list = []
    deepest = 0
    for width, inline in starts:
        while stack and stack[-1] >= width:
            stack.pop()
        stack.append(width)
        deepest = max(deepest, len(stack) + inline)
    return deepest


def _xml_depth(text: str) -> int:
    tags = _XML_TAG.findall(_XML_SKIP.sub("", text))
    steps = np.array([0 if close and not opening else (-1 if opening else 1) for opening, close in
                      ((o == "/", c == "/") for o, c in tags)], dtype=np.int8)
    return _max_rise(steps)


def nesting_depth(text: str, syntax: str) -> int:
    """An upper estimate of how deep `text` nests, for `syntax` "yaml" (block and flow; JSON is
    flow YAML), "json", "python" or "xml"."""
    if syntax == "xml":
        return _xml_depth(text)
    depth = _flow_depth(text)
    if syntax == "yaml":
        depth += _block_depth(text)
    return depth


def check_nesting(text: str, where, syntax: str, max_depth: int = MAX_NESTING) -> None:
    """InputError when `text` nests deeper than `max_depth` (see nesting_depth)."""
    if nesting_depth(text, syntax) > max_depth:
        raise InputError(f"{shown(where)}: nested more than {max_depth} levels deep (a camera, target or "
                         "manifest file nests a few)")


def _check_digits(token: str, where) -> None:
    digits = sum(c.isdigit() for c in token)
    if digits > MAX_INT_DIGITS:
        raise InputError(f"{shown(where)}: a number of {digits} digits (at most {MAX_INT_DIGITS})")


# -- YAML ------------------------------------------------------------------------------------------


class _BoundedConstructor(yaml.constructor.SafeConstructor):
    def construct_yaml_int(self, node):
        _check_digits(str(node.value), self._where)
        return super().construct_yaml_int(node)


_BoundedConstructor.add_constructor("tag:yaml.org,2002:int", _BoundedConstructor.construct_yaml_int)


class _BoundedLoader(yaml.reader.Reader, yaml.scanner.Scanner, yaml.parser.Parser, yaml.composer.Composer,
                     _BoundedConstructor, yaml.resolver.Resolver):
    """yaml.SafeLoader that counts while it composes: nesting depth, and the nodes the document
    expands to with its aliases followed."""

    def __init__(self, stream, where, aliases: bool, max_depth: int, max_nodes: int):
        yaml.reader.Reader.__init__(self, stream)
        yaml.scanner.Scanner.__init__(self)
        yaml.parser.Parser.__init__(self)
        yaml.composer.Composer.__init__(self)
        _BoundedConstructor.__init__(self)
        yaml.resolver.Resolver.__init__(self)
        self._where, self._aliases, self._max_depth, self._max_nodes = where, aliases, max_depth, max_nodes
        self._depth = 0
        self._expanded: dict = {}   # id(node) -> nodes it stands for, aliases followed

    def _too_big(self) -> InputError:
        return InputError(f"{shown(self._where)}: its aliases (*name) expand to more than {self._max_nodes} values")

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            if not self._aliases:
                mark = event.start_mark
                raise InputError(f"{shown(self._where)}: line {mark.line + 1}: YAML aliases (*{event.anchor}) are not "
                                 "read in this file; write the values out")
            anchored = self.anchors.get(event.anchor)
            if anchored is not None and id(anchored) not in self._expanded:
                raise InputError(f"{shown(self._where)}: line {event.start_mark.line + 1}: the alias *{event.anchor} "
                                 "is inside the value it names (a value cannot contain itself)")
            return super().compose_node(parent, index)
        self._depth += 1
        if self._depth > self._max_depth:
            mark = self.peek_event().start_mark
            raise InputError(f"{shown(self._where)}: line {mark.line + 1}: nested more than {self._max_depth} "
                             "levels deep")
        node = super().compose_node(parent, index)
        self._depth -= 1
        if isinstance(node, yaml.SequenceNode):
            children = node.value
        elif isinstance(node, yaml.MappingNode):
            children = [n for pair in node.value for n in pair]
        else:
            children = []
        size = 1 + sum(self._expanded.get(id(child), 1) for child in children)
        self._expanded[id(node)] = size
        if size > self._max_nodes:
            raise self._too_big()
        return node


def load_yaml(text: str, where, *, aliases: bool = False, max_depth: int = MAX_NESTING,
              max_nodes: int = MAX_YAML_NODES, max_bytes: int = YAML_MAX_BYTES) -> Any:
    """One YAML document, as yaml.safe_load reads it, within the limits above; InputError naming
    `where` (and the line) for a syntax error, too deep a nesting, an alias (aliases=False) or
    aliases expanding to more than max_nodes values, an integer of more than MAX_INT_DIGITS digits,
    more than max_bytes of text (parsing YAML takes seconds per MB)."""
    size = len(text.encode("utf-8", "replace")) if len(text) * 4 > max_bytes else len(text)
    if size > max_bytes:
        raise InputError(f"{shown(where)}: {_format_bytes(size)} of YAML, more than the {_format_bytes(max_bytes)} "
                         "such a file can be")
    loader = None
    try:
        loader = _BoundedLoader(text, where, aliases, max_depth, max_nodes)   # checks the characters
        return loader.get_single_data()
    except InputError:   # a limit above (InputError is a ValueError: caught before the handler below)
        raise
    except yaml.YAMLError as error:
        first = str(error).splitlines()[0] if str(error) else type(error).__name__
        mark = getattr(error, "problem_mark", None)
        line = f" (line {mark.line + 1})" if mark is not None else ""
        raise InputError(f"{shown(where)}: not valid YAML{line}: {one_line(first)}") from None
    except (RecursionError, MemoryError):
        raise InputError(f"{shown(where)}: nested too deep or too large to read") from None
    except ValueError as error:   # a conversion PyYAML does not wrap (a timestamp out of range...)
        raise InputError(f"{shown(where)}: not valid YAML: {one_line(str(error))[:120]}") from None
    finally:
        if loader is not None:
            loader.dispose()


# -- JSON and Python literals -------------------------------------------------------------------------


def load_json(text: str, where, max_depth: int = MAX_NESTING) -> Any:
    """JSON within the nesting and integer-length limits; InputError naming `where` otherwise."""
    check_nesting(text, where, "json", max_depth)

    def integer(token: str) -> int:
        _check_digits(token, where)
        return int(token)

    try:
        return json.loads(text, parse_int=integer)
    except InputError:
        raise
    except (ValueError, RecursionError) as error:
        raise InputError(f"{shown(where)}: not valid JSON ({one_line(str(error))[:120]})") from None


def load_python_literal(text: str, where, what: str = "a Python literal", max_depth: int = MAX_NESTING) -> Any:
    """A Python literal (dict, list, str, numbers, True/False/None; comments allowed) by
    ast.literal_eval, within the nesting and integer-length limits."""
    check_nesting(text, where, "python", max_depth)
    for token in _LONG_INTEGER.findall(_QUOTED.sub('""', text)):
        _check_digits(token, where)
    try:
        return ast.literal_eval(text.strip())
    except (ValueError, SyntaxError, TypeError, MemoryError, RecursionError):
        raise InputError(f"{shown(where)}: not {what}") from None
