"""Typed reading of parsed TOML tables with one-line errors.

One reader for the scene, optimisation and sweep files.  Each file kind passes
``fail(path, message)``, which raises its own error class (the key path leads its
message), and a :class:`Style` for the few messages whose wording differs between
the kinds.  :class:`Reader` checks single values, :class:`Table` a table's keys.

:func:`check_document` bounds what any value of a parsed file may be (scene, sweep,
optimisation and dataset files alike, applied by :func:`beltjax.textfile.loads_toml`):
integers within 64 bits, strings, arrays and keys of bounded length, tables and arrays
nested at most :data:`MAX_DEPTH` deep.  :func:`show` is how a message quotes a value: never
more than :data:`SHOW_CHARS` characters of it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NoReturn

#: tables and arrays nested deeper than this (counting from the top-level table) are refused
MAX_DEPTH = 20
#: the longest array (elements); a sweep has at most 100000 cases
MAX_ARRAY = 100_000
#: the longest string (characters) by the key it is at; "name" covers every pulley, record,
#: configuration and variable name, "description" the free text of a file
MAX_STRING = {"description": 10_000, "name": 100}
#: the longest string at any other key (a file name, a parameter path, a label, a choice)
MAX_STRING_OTHER = 1_000
#: the longest key (characters)
MAX_KEY = 100
#: integers must fit a signed 64-bit integer (and so a float64 too)
INT64 = 2**63
#: a message shows at most this many characters of a value
SHOW_CHARS = 40


def _digits(v: int) -> int:
    """Decimal digits of the integer ``v`` (without converting it to text: Python refuses
    that beyond 4300 digits)."""
    a = abs(v)
    if a < 10**15:
        return len(str(a))
    n = int(math.log10(a)) + 1
    return n + (a >= 10**n) - (a < 10 ** (n - 1))


def show(v) -> str:
    """``v`` as a message quotes it: its repr, cut to :data:`SHOW_CHARS` characters with the
    length said ("'aaaa...' (2000000 characters)", "an integer of 400 digits")."""
    if isinstance(v, bool):
        return str(v).lower()
    if isinstance(v, int) and abs(v) >= 10**SHOW_CHARS:
        return f"an integer of {_digits(v)} digits"
    if isinstance(v, str) and len(v) > SHOW_CHARS:
        return f"{v[:SHOW_CHARS]!r}... ({len(v)} characters)"
    if isinstance(v, (list, tuple)) and len(v) > 8:
        return show(list(v[:8]))[:-1] + f", ...] ({len(v)} elements)"
    r = repr(v)
    return r if len(r) <= 2 * SHOW_CHARS else r[: 2 * SHOW_CHARS] + "..."


def show_key(path: str) -> str:
    """A key path as a message names it: each part cut to :data:`SHOW_CHARS` characters, the
    whole to 4 x that."""
    parts = [p if len(p) <= SHOW_CHARS else p[:SHOW_CHARS] + "..." for p in str(path).split(".")]
    s = ".".join(parts)
    return s if len(s) <= 4 * SHOW_CHARS else s[: 4 * SHOW_CHARS] + "..."


def describe(v) -> str:
    """A value as error messages name it: ``a string ('x')``, ``a table``, ``float (inf)``."""
    if isinstance(v, bool):
        return f"a boolean ({str(v).lower()})"
    if isinstance(v, str):
        return f"a string ({show(v)})"
    if isinstance(v, dict):
        return "a table"
    if isinstance(v, list):
        return "an array"
    if isinstance(v, int) and abs(v) >= 10**SHOW_CHARS:
        return show(v)
    return f"{type(v).__name__} ({show(v)})"


def _scalar_problem(v, limit: int) -> str | None:
    """Why the scalar ``v`` (at a key whose strings may have ``limit`` characters) cannot be carried."""
    if isinstance(v, int) and not isinstance(v, bool) and not -INT64 <= v < INT64:
        return (f"an integer of {_digits(v)} digits: more than a 64-bit integer or a float64 holds exactly "
                "(write a float such as 1e20 for a real number)")
    if isinstance(v, str) and len(v) > limit:
        return f"a string of {len(v)} characters, longer than the limit of {limit}"
    return None


def check_document(data, fail: Callable[[str, str], NoReturn], key: str = "") -> None:
    """Refuse values of a parsed TOML document that no key of beltjax can carry: an integer
    beyond 64 bits, a string longer than its limit (:data:`MAX_STRING`), an array longer than
    :data:`MAX_ARRAY`, a key longer than :data:`MAX_KEY`, tables or arrays nested deeper than
    :data:`MAX_DEPTH`.  ``fail(key path, message)`` names the first one found (depth first).
    Cost: one pass over the values (about 0.1 s per million numbers)."""
    bad = _scalar_problem(data, MAX_STRING.get(key.rsplit(".", 1)[-1], MAX_STRING_OTHER))
    if bad:
        fail(show_key(key), bad)
    # (container, its path, the key it is at, depth, the path without array indices past the first)
    stack = [(data, key, key.rsplit(".", 1)[-1], 0, key)] if isinstance(data, (dict, list)) else []
    while stack:
        v, path, last, depth, named = stack.pop()
        if depth >= MAX_DEPTH:
            fail(show_key(named), f"tables and arrays nested more than {MAX_DEPTH} deep")
        inner = []
        if isinstance(v, list):
            if len(v) > MAX_ARRAY:
                fail(show_key(path), f"an array of {len(v)} elements, more than the limit of {MAX_ARRAY}")
            limit = MAX_STRING.get(last, MAX_STRING_OTHER)
            for i, x in enumerate(v):
                if type(x) is float:
                    continue
                if isinstance(x, (dict, list)):
                    inner.append((x, f"{path}[{i}]", last, depth + 1, named if named.endswith("]") else f"{path}[{i}]"))
                elif (bad := _scalar_problem(x, limit)) is not None:
                    fail(show_key(f"{path}[{i}]"), bad)
        else:
            for k, x in v.items():
                p = f"{path}.{k}" if path else k
                if len(k) > MAX_KEY:
                    fail(show_key(p), f"a key of {len(k)} characters, longer than the limit of {MAX_KEY}")
                if isinstance(x, (dict, list)):
                    inner.append((x, p, k, depth + 1, p))
                elif (bad := _scalar_problem(x, MAX_STRING.get(k, MAX_STRING_OTHER))) is not None:
                    fail(show_key(p), bad)
        stack.extend(reversed(inner))


@dataclass(frozen=True)
class Style:
    """Wording of the messages that differ between file kinds (the defaults: scene and sweep files).

    unknown_where: an unknown key names its table, "unknown key (allowed in X: ...)";
        else "unknown key (allowed: ...)".
    finite: a non-number and a non-finite number both read "expected a finite number, got ...";
        else "expected a number, got ..." and "must be finite, got ...".
    choose: a string outside its choices reads "unknown value 'x'; choose one of a, b" and a
        missing one "missing (required key); one of a, b"; else "must be one of 'a', 'b', got 'x'"
        and "missing (required key)".
    top: the key named when the top-level table is not a table.
    """

    unknown_where: bool = True
    finite: bool = False
    choose: bool = False
    top: str = ""


@dataclass(frozen=True)
class Reader:
    """Checks of single values named by their key ``path``; ``fail(path, message)`` raises."""

    fail: Callable[[str, str], NoReturn]
    style: Style = Style()

    def table(self, data, key: str, allowed) -> Table:
        """``data`` as the table at ``key`` ("" for the top level) with keys ``allowed``."""
        return Table(data, key, allowed, self)

    def number(self, path: str, v, *, positive: bool = False, nonnegative: bool = False) -> float:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.fail(path, f"expected {'a finite number' if self.style.finite else 'a number'}, got {describe(v)}")
        if isinstance(v, int) and not -INT64 <= v < INT64:
            self.fail(path, f"expected a number a float64 holds, got {show(v)}")
        if not math.isfinite(v):
            self.fail(path, f"expected a finite number, got {describe(v)}" if self.style.finite
                      else f"must be finite, got {v!r}")
        if positive and not v > 0:
            self.fail(path, f"must be > 0, got {v!r}")
        if nonnegative and not v >= 0:
            self.fail(path, f"must be >= 0, got {v!r}")
        return float(v)

    def integer(self, path: str, v, *, minimum: int | None = None, maximum: int | None = None) -> int:
        if isinstance(v, bool) or not isinstance(v, int):
            self.fail(path, f"expected an integer, got {describe(v)}")
        if minimum is not None and v < minimum:
            self.fail(path, f"must be >= {minimum}, got {show(v)}")
        if maximum is not None and v > maximum:
            self.fail(path, f"must be <= {maximum}, got {show(v)}")
        if not -INT64 <= v < INT64:
            self.fail(path, f"expected a 64-bit integer, got {show(v)}")
        return int(v)

    def vector2(self, path: str, v) -> list[float]:
        if not isinstance(v, list) or len(v) != 2:
            self.fail(path, f"expected [x, y] (two numbers), got {describe(v) if not isinstance(v, list) else show(v)}")
        for i, x in enumerate(v):
            if isinstance(x, bool) or not isinstance(x, (int, float)):
                self.fail(path, f"expected [x, y] (two numbers), element {i} is {describe(x)}")
            if isinstance(x, int) and not -INT64 <= x < INT64:
                self.fail(path, f"expected [x, y] (two numbers), element {i} is {show(x)}")
            if not math.isfinite(x):
                self.fail(path, f"must be finite, got {show(v)}")
        return [float(x) for x in v]

    def boolean(self, path: str, v) -> bool:
        if not isinstance(v, bool):
            self.fail(path, f"expected true or false, got {describe(v)}")
        return v

    def string(self, path: str, v, *, choices=None, nonempty: bool = False) -> str:
        """A string (``nonempty``: not ""), one of ``choices`` when given."""
        if not isinstance(v, str) or (nonempty and not v):
            self.fail(path, f"expected {'a non-empty string' if nonempty else 'a string'}, got {describe(v)}")
        if choices is not None and v not in choices:
            if self.style.choose:
                self.fail(path, f"unknown value {show(v)}; choose one of {', '.join(choices)}")
            self.fail(path, f"must be one of {', '.join(repr(c) for c in choices)}, got {show(v)}")
        return v

    def strings(self, path: str, v) -> list[str]:
        """An array of distinct strings."""
        if not isinstance(v, list):
            self.fail(path, f"expected an array of strings, got {describe(v)}")
        for i, x in enumerate(v):
            if not isinstance(x, str):
                self.fail(path, f"expected an array of strings, element {i} is {describe(x)}")
        seen = set()
        for x in v:
            if x in seen:
                self.fail(path, f"{show(x)} appears twice")
            seen.add(x)
        return list(v)


class Table:
    """A TOML table being read: checked for unknown keys, then typed getters by key.

    The top-level table (``key`` "") is first checked whole by :func:`check_document`.

    A getter returns ``default`` for a missing key unless ``required`` (then it fails).
    """

    def __init__(self, data, key: str, allowed, reader: Reader):
        if not isinstance(data, dict):
            reader.fail(key or reader.style.top, f"expected a table, got {describe(data)}")
        if not key:  # a whole document (also one given as a dict, not read from a file): its bounds
            check_document(data, reader.fail)
        self.data, self.key, self.allowed, self.reader = data, key, allowed, reader
        for k in data:
            if k not in allowed:
                if reader.style.unknown_where:
                    where = f"in {key}" if key else "at the top level"
                    reader.fail(self.path(k), f"unknown key (allowed {where}: {', '.join(allowed)})")
                reader.fail(self.path(k), f"unknown key (allowed: {', '.join(allowed)})")

    def path(self, k: str) -> str:
        return show_key(f"{self.key}.{k}" if self.key else k)

    def fail(self, k: str, msg: str) -> NoReturn:
        self.reader.fail(self.path(k), msg)

    def has(self, k: str) -> bool:
        return k in self.data

    def raw(self, k: str, required: bool, missing: str = "missing (required key)") -> Any:
        """The value at ``k`` unchecked; None when missing and not required."""
        if k not in self.data:
            if required:
                self.fail(k, missing)
            return None
        return self.data[k]

    def number(self, k, *, required=True, default=None, positive=False, nonnegative=False):
        v = self.raw(k, required)
        return default if v is None else self.reader.number(self.path(k), v, positive=positive,
                                                            nonnegative=nonnegative)

    def integer(self, k, *, required=True, default=None, minimum=None, maximum=None):
        v = self.raw(k, required)
        return default if v is None else self.reader.integer(self.path(k), v, minimum=minimum, maximum=maximum)

    def vector2(self, k, *, required=True, default=None):
        v = self.raw(k, required)
        return default if v is None else self.reader.vector2(self.path(k), v)

    def boolean(self, k, *, required=False, default=False):
        v = self.raw(k, required)
        return default if v is None else self.reader.boolean(self.path(k), v)

    def string(self, k, *, required=True, default=None, choices=None, nonempty=False):
        missing = "missing (required key)"
        if choices is not None and self.reader.style.choose:
            missing += f"; one of {', '.join(choices)}"
        v = self.raw(k, required, missing)
        return default if v is None else self.reader.string(self.path(k), v, choices=choices, nonempty=nonempty)

    def strings(self, k, *, required=True, default=None):
        v = self.raw(k, required)
        return default if v is None else self.reader.strings(self.path(k), v)

    def tables(self, k) -> list:
        """The array of tables ``[[k]]`` (default []); its tables are read by the caller."""
        v = self.data.get(k, [])
        if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
            self.fail(k, f"expected an array of tables [[{k}]], got {describe(v)}")
        return v
