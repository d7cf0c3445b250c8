"""Writing TOML: a document (nested dicts and lists of numbers, strings, booleans) as text that
``tomllib`` reads back to the same values, floats to the last bit.

Hand-written: the brief's dependencies carry no TOML writer (``tomllib`` only reads), and a
scene needs only the plain forms: top-level keys, ``[table]``, ``[[array of tables]]``, arrays
of scalars and inline tables inside a table.  Comments are given per table (``comments``).
"""

from __future__ import annotations

import math
import re
from typing import Any

_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def key(k: str) -> str:
    """A TOML key: bare where it may be, else a quoted basic string."""
    return k if _BARE.match(k) else string(k)


def string(s: str) -> str:
    """A TOML basic string: quote, backslash and control characters escaped (the rest as is:
    TOML files are UTF-8)."""
    out = []
    for ch in s:
        if ch == '"':
            out.append('\\"')
        elif ch == "\\":
            out.append("\\\\")
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04x}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def value(v: Any) -> str:
    """A TOML value: bool, int, float (``repr``: the shortest text that reads back to the same
    float64; inf and nan as TOML spells them), str, a list of these, or a dict (inline table)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return string(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{key(k)} = {value(x)}" for k, x in v.items()) + "}"
    raise TypeError(f"no TOML value for {type(v).__name__}")


def _is_table(v) -> bool:
    return isinstance(v, dict)


def _is_table_array(v) -> bool:
    return isinstance(v, (list, tuple)) and len(v) > 0 and all(isinstance(x, dict) for x in v)


def _pairs(table: dict) -> list[str]:
    return [f"{key(k)} = {value(v)}" for k, v in table.items()]


def dumps(doc: dict, comments: dict[str, str] | None = None) -> str:
    """The TOML text of ``doc``: its plain keys first, then each table (``[name]``) and each
    array of tables (``[[name]]``, one per element) in the dict's order.  A table's own nested
    dicts are written inline.  ``comments``: {table name: a comment line written above it}
    ("" for the top)."""
    comments = comments or {}
    lines = []
    if comments.get(""):
        lines += [f"# {c}" for c in comments[""].splitlines()]
    plain = {k: v for k, v in doc.items() if not _is_table(v) and not _is_table_array(v)}
    lines += _pairs(plain)
    for k, v in doc.items():
        if k in plain:
            continue
        blocks = [v] if _is_table(v) else list(v)
        for i, block in enumerate(blocks):
            lines.append("")
            if i == 0 and comments.get(k):
                lines += [f"# {c}" for c in comments[k].splitlines()]
            lines.append(f"[{key(k)}]" if _is_table(v) else f"[[{key(k)}]]")
            lines += _pairs(block)
    return "\n".join(lines).lstrip("\n") + "\n"
