"""Reading input files: one reader for scene, sweep, optimisation and dataset files and CSV data.

Every file beltjax reads goes through :func:`read_text` (and TOML files through
:func:`load_toml`, TOML text through :func:`loads_toml`):

* only a regular file is read: a named pipe, a device such as ``/dev/zero``, a socket or a
  directory is refused from ``stat`` alone, without opening it (a pipe is never opened for
  reading, so nothing blocks); the open itself is non-blocking and checked again with
  ``fstat`` against a file swapped in between;
* its size is bounded (:data:`LIMITS`, per kind of file) and at most limit + 1 bytes are read,
  so a file that grows or lies about its size cannot exhaust memory;
* a UTF-8 byte-order mark is accepted and dropped; text that is not UTF-8 is refused with the
  line and column of the first bad byte;
* TOML is parsed by ``tomllib`` after a scan (:func:`shape_problem`) that refuses what would
  make ``tomllib`` recurse without bound or take quadratic time (arrays or inline tables nested
  deeper than :data:`MAX_NESTING`, dotted keys of more than :data:`MAX_KEY_PARTS` parts, a number
  written with more than :data:`MAX_NUMBER_CHARS` characters); then every value is checked by
  :func:`beltjax.tomltable.check_document` (integers, string and array lengths, nesting, keys).

Errors are one line starting with the file or the key (``fail(key, message)`` raises the caller's
error class; by default :class:`~beltjax.errors.BeltjaxError`).  No message quotes the file's
contents: a TOML syntax error gives tomllib's description with line and column only.
"""

from __future__ import annotations

import os
import pathlib
import re
import stat
import tomllib
from collections.abc import Callable
from typing import NoReturn

from beltjax import tomltable
from beltjax.errors import BeltjaxError

Fail = Callable[[str, str], NoReturn]

MIB = 1 << 20
#: the largest file of each kind (bytes); every shipped file is below 40 kB
LIMITS = {"scene": 8 * MIB, "sweep": 8 * MIB, "optimisation": 8 * MIB, "dataset": 8 * MIB, "csv": 64 * MIB}
NOUNS = {"scene": "scene file", "sweep": "sweep file", "optimisation": "optimisation file",
         "dataset": "dataset file", "csv": "data file"}
#: arrays and inline tables nested deeper than this are refused before parsing
MAX_NESTING = tomltable.MAX_DEPTH
#: a dotted key or table header of more parts is refused before parsing (tomllib is quadratic in it)
MAX_KEY_PARTS = tomltable.MAX_DEPTH
#: a number written with more characters is refused before parsing (Python refuses int() beyond 4300 digits)
MAX_NUMBER_CHARS = 1000

BOM = "\ufeff"


def _raise(key: str, message: str) -> NoReturn:
    raise BeltjaxError(f"{key}: {message}", key)


def keyed(fail: Fail) -> Fail:
    """``fail`` called with the message already led by its key: for error classes that lead a
    message with its key only when the message does not start with the key's text already."""

    def f(key: str, message: str) -> NoReturn:
        fail(key, f"{key}: {message}")

    return f


def _a(noun: str) -> str:
    return f"{'an' if noun[0] in 'aeiou' else 'a'} {noun}"


def _size(n: int) -> str:
    return f"{n / MIB:.1f} MiB" if n >= MIB else f"{n} bytes"


def _not_regular(mode: int) -> str:
    if stat.S_ISFIFO(mode):
        return "a named pipe"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "something other than a file"


def outside_problem(base, name: str, shown: str, folder: str, rule: str, absolute_rule: str) -> str | None:
    """Why the file ``name`` (shown as ``shown``) is not a file inside the folder ``base``, or
    None: a NUL character, an absolute path, a path through ``..`` or a link that resolves
    outside (or not at all).  ``folder`` names the folder, ``rule`` says where its files lie,
    ``absolute_rule`` how they are named (the words of the caller's file kind)."""
    if "\0" in name:
        return "a file name cannot hold a NUL character"
    pure = pathlib.PurePath(name)
    if pure.is_absolute():
        return f"{shown} is an absolute path: {absolute_rule}"
    if ".." in pure.parts:
        return f"{shown} leads out of {folder} through '..': {rule}"
    root = pathlib.Path(base).resolve()
    try:
        real = (root / pure).resolve()
    except (OSError, RuntimeError):  # a loop of links
        return f"{shown}: a link that cannot be resolved"
    if not real.is_relative_to(root):
        return f"{shown} is a link to a file outside {folder}: {rule}"
    return None


def file_name(path, kind: str, fail: Fail = _raise) -> str:
    """``path`` (str or path-like) as a str, else ``fail("path", message)`` (None, bytes, a number:
    what a Python caller may pass for a file of ``kind``)."""
    if not isinstance(path, (str, os.PathLike)) or not isinstance(p := os.fspath(path), str):
        fail("path", f"the {NOUNS[kind]} must be given as a file name (str or path), got {type(path).__name__}")
    return p


def read_text(path, kind: str, fail: Fail = _raise) -> str:
    """The text of the file at ``path`` (str or path-like), a file of ``kind`` (a key of
    :data:`LIMITS`): a regular UTF-8 file of at most ``LIMITS[kind]`` bytes, its byte-order
    mark dropped.  Anything else is ``fail(path, message)``; pipes and devices are never opened."""
    p = file_name(path, kind, fail)
    noun, limit = NOUNS[kind], LIMITS[kind]
    if not p:
        fail(p, f"empty file name for the {noun}")
    if "\0" in p:
        fail(p.replace("\0", "\\0"), "a file name cannot hold a NUL character")
    try:
        st = os.stat(p)
    except (FileNotFoundError, NotADirectoryError):
        fail(p, f"{noun} not found")
    except OSError as e:
        fail(p, f"cannot read: {e.strerror or type(e).__name__}")
    if stat.S_ISDIR(st.st_mode):
        fail(p, f"is a directory, not {_a(noun)}")
    if not stat.S_ISREG(st.st_mode):
        fail(p, f"is {_not_regular(st.st_mode)}, not a regular file ({_a(noun)} must be one)")
    if st.st_size > limit:
        fail(p, f"{_size(st.st_size)}, more than the limit of {_size(limit)} for {_a(noun)}")
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(p, flags)
    except OSError as e:
        fail(p, f"cannot read: {e.strerror or type(e).__name__}")
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):  # replaced between stat and open
            fail(p, f"is {_not_regular(mode)}, not a regular file ({_a(noun)} must be one)")
        chunks, n = [], 0
        while n <= limit:
            b = os.read(fd, min(limit + 1 - n, MIB))
            if not b:
                break
            chunks.append(b)
            n += len(b)
    except OSError as e:
        fail(p, f"cannot read: {e.strerror or type(e).__name__}")
    finally:
        os.close(fd)
    data = b"".join(chunks)
    if len(data) > limit:
        fail(p, f"more than the limit of {_size(limit)} for {_a(noun)}")
    return decode(data, p, fail)


def decode(data: bytes, source: str, fail: Fail = _raise) -> str:
    """``data`` as UTF-8 text without its byte-order mark; a bad byte is ``fail(source, ...)``
    naming its line and column (not the byte)."""
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        col = e.start - (data.rfind(b"\n", 0, e.start) + 1) + 1
        fail(source, f"not a UTF-8 text file ({e.reason} at line {line}, column {col})")


def load_toml(path, kind: str, fail: Fail = _raise) -> dict:
    """The TOML file at ``path`` (see :func:`read_text`) parsed and checked (see :func:`loads_toml`)."""
    return loads_toml(read_text(path, kind, fail), os.fspath(path), fail)


# tomllib's messages: a description, then "(at line L, column C)" or "(at end of document)"
_AT = re.compile(r"^(.*?)\s*\(at (line \d+, column \d+|end of document)\)\s*$", re.S)
# quoted text in a description: kept only when it is one punctuation character of the grammar
_QUOTED = re.compile(r"""'(?:[^'\\]|\\.)*'|"(?:[^"\\]|\\.)*"|\([^)]*\)""")


def _syntax_message(exc: Exception) -> str:
    """tomllib's error as "malformed TOML: <description> (at line L, column C)", without any text
    from the file (a quoted character, a key) in it."""
    m = _AT.match(str(exc))
    what, where = (m.group(1), m.group(2)) if m else (str(exc), "")

    def keep(q):
        s = q.group(0)
        return s if len(s) == 3 and s[0] in "'\"" and s[1] in "=[]{},.\"'" else ""

    what = " ".join(_QUOTED.sub(keep, what).split()) or "invalid TOML"
    return f"malformed TOML: {what[:120]}" + (f" (at {where})" if where else "")


def loads_toml(text: str, source: str, fail: Fail = _raise) -> dict:
    """TOML ``text`` (from ``source``, the file or "<string>") parsed and checked.

    A leading byte-order mark is dropped.  Before parsing, :func:`shape_problem` refuses
    nesting, dotted keys and number lengths that tomllib cannot take in bounded time and stack;
    a syntax error is "malformed TOML" with tomllib's line and column; after parsing,
    :func:`beltjax.tomltable.check_document` checks every value.  Errors: ``fail(key, message)``.
    """
    if text.startswith(BOM):
        text = text[1:]
    bad = shape_problem(text)
    if bad is not None:
        key, message = bad
        fail(key or source, message)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        fail(source, _syntax_message(e))
    except RecursionError:  # not expected after shape_problem; never a traceback
        fail(source, f"malformed TOML: nested too deeply (more than {MAX_NESTING} levels)")
    except (ValueError, OverflowError, MemoryError) as e:
        fail(source, f"malformed TOML: a value that cannot be read ({type(e).__name__})")
    tomltable.check_document(data, fail)
    return data


# --------------------------------------------------------------------------- the scan before parsing

_TOKEN = re.compile(
    r'(?P<s>"""[^"\\]*(?:(?:\\[\s\S]|"(?!""))[^"\\]*)*"""'  # multi-line basic string
    r"|'''[^']*(?:'(?!'')[^']*)*'''"                          # multi-line literal string
    r'|"[^"\\\n]*(?:\\.[^"\\\n]*)*"?'                         # basic string (to the line's end if open)
    r"|'[^'\n]*'?)"                                           # literal string
    r"|(?P<c>#[^\n]*)|(?P<n>\n)|(?P<p>[\[\]{}=])"
    r"""|(?P<r>[^\[\]{}="'#\n]+)"""                           # a run of the rest: keys, numbers, commas
)
_LONG = re.compile(r"[^\s,]{%d,}" % (MAX_NUMBER_CHARS + 1))


def shape_problem(text: str) -> tuple[str, str] | None:
    """(key, message) for TOML ``text`` that tomllib cannot parse in bounded stack and time, else None.

    A token scan (strings and comments skipped; a run of numbers, commas and spaces is one token)
    that refuses arrays or inline tables nested more than :data:`MAX_NESTING` deep, a dotted key
    or table header of more than :data:`MAX_KEY_PARTS` parts and a number of more than
    :data:`MAX_NUMBER_CHARS` characters.  ``key`` is the key being read (table header + key,
    shortened), "" when none.  The scan does not validate TOML (tomllib does); it only bounds
    these three things.
    """
    table, name = "", []        # the current [table] and the key (parts) being read or valued
    stack: list[str] = []       # open "[" / "{" of the value being read
    state, header = "start", False  # start (of a line at depth 0) | key | ikey (inline table's) | value
    parts, line = 1, 1

    def where() -> str:
        return tomltable.show_key(".".join(x for x in (table, ".".join(name)) if x))

    def too_many() -> tuple[str, str]:
        return where(), f"a dotted key of more than {MAX_KEY_PARTS} parts (line {line})"

    for m in _TOKEN.finditer(text):
        kind, tok = m.lastgroup, m.group()
        if kind == "c":
            continue
        if kind == "n":
            line += 1
            if not stack:
                state = "start"
            continue
        if kind == "s":
            line += tok.count("\n")
        elif kind == "r" and tok.isspace():
            continue
        if state == "start":
            header, state, parts, name = tok == "[", "key", 1, []
            if header:
                table = ""
                continue
        if state in ("key", "ikey"):
            if kind == "r":
                if state == "key" and len(name) < 8:
                    name += [x.strip()[:40] for x in tok.split(".", 8)[:8] if x.strip()]
                parts += tok.count(".")
                if parts > MAX_KEY_PARTS:
                    return too_many()
                continue
            if kind == "s":
                if state == "key" and len(name) < 8:
                    name.append(tok.strip("\"'")[:40])
                continue
            if header and tok == "[":
                continue
            if header and tok == "]":
                table, name, state = ".".join(name), [], "value"
                continue
            if tok == "=":
                state = "value"
                continue
            state = "value"  # not a key: malformed, tomllib says where
        if tok in ("[", "{"):
            stack.append(tok)
            if len(stack) > MAX_NESTING:
                return where(), f"arrays or inline tables nested more than {MAX_NESTING} deep (line {line})"
            if tok == "{":
                state, parts = "ikey", 1
        elif tok in ("]", "}"):
            if stack:
                stack.pop()
        elif kind == "r":
            long = _LONG.search(tok)
            if long:
                return where(), (f"a value written with {len(long.group())} characters, more than the limit of "
                                 f"{MAX_NUMBER_CHARS} (line {line})")
            if stack and stack[-1] == "{" and "," in tok:  # an inline table's next key
                state, parts = "ikey", 1 + tok.rsplit(",", 1)[1].count(".")
                if parts > MAX_KEY_PARTS:
                    return too_many()
    return None
