"""The one reader of input files (beltjax.textfile) and the value bounds of beltjax.tomltable.

No compilation: every check here is about reading and parsing.  The command-line view of the
same errors (exit 2, one line) is in tests/test_robustness_inputs.py.
"""

from __future__ import annotations

import json
import os
import pathlib
import random
import signal
import tomllib

import pytest

from beltjax import textfile, tomltable
from beltjax.errors import BeltjaxError
from identification.data import DataError, dataset_file

REPO = pathlib.Path(__file__).resolve().parents[1]
SHIPPED = sorted([*REPO.glob("scenes/**/*.toml"), *REPO.glob("identification/examples/**/*.toml")])


def _error(fn, *args) -> str:
    with pytest.raises(BeltjaxError) as e:
        fn(*args)
    msg = str(e.value)
    assert "\n" not in msg
    return msg


def test_every_shipped_file_reads():
    assert len(SHIPPED) > 20
    for p in SHIPPED:
        assert textfile.load_toml(p, "scene") == tomllib.loads(p.read_text()), p


def test_a_named_pipe_is_never_opened(tmp_path):
    """stat before open: reading a pipe nobody writes to would block; the alarm turns a block
    into a failure instead of a hang."""
    p = tmp_path / "pipe.toml"
    os.mkfifo(p)

    def alarm(*_):
        raise TimeoutError("blocked on the named pipe")

    old = signal.signal(signal.SIGALRM, alarm)
    signal.alarm(20)
    try:
        assert "is a named pipe, not a regular file" in _error(textfile.read_text, p, "scene")
        assert "is a device" in _error(textfile.read_text, "/dev/zero", "csv")
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def test_size_limit_utf8_and_byte_order_mark(tmp_path):
    big = tmp_path / "big.toml"
    with open(big, "wb") as f:
        f.truncate(textfile.LIMITS["sweep"] + 1)
    assert "more than the limit of 8.0 MiB for a sweep file" in _error(textfile.read_text, big, "sweep")
    exact = tmp_path / "exact.csv"
    exact.write_bytes(b"a" * 1000)
    assert textfile.read_text(exact, "csv") == "a" * 1000
    bom = tmp_path / "bom.toml"
    bom.write_bytes(b"\xef\xbb\xbfa = 1\n")
    assert textfile.load_toml(bom, "scene") == {"a": 1}
    assert textfile.loads_toml("\ufeffa = 1\n", "<string>") == {"a": 1}
    bad = tmp_path / "bad.toml"
    bad.write_bytes(b"a = 1\nb = '\xc3\x28 SECRET'\n")
    msg = _error(textfile.read_text, bad, "scene")
    assert "not a UTF-8 text file (invalid continuation byte at line 2, column 6)" in msg and "SECRET" not in msg
    assert "dataset file not found" in _error(textfile.read_text, tmp_path / "none.toml", "dataset")
    assert "is a directory, not an optimisation file" in _error(textfile.read_text, tmp_path, "optimisation")


@pytest.mark.parametrize("text", [
    "a = 1 SECRET", "a = 'SECRET", "[a]\nb = 1\n[a]\nSECRET = 1", "a = { SECRET = 1, SECRET = 2 }",
    "SECRET.x = 1\nSECRET = 2", "a = \"SECRET\x01\"", "a = [1, 2 SECRET]",
])
def test_syntax_errors_name_line_and_column_only(text):
    msg = _error(textfile.loads_toml, text, "f.toml")
    assert msg.startswith("f.toml: malformed TOML: ") and "SECRET" not in msg, msg


def _random_toml(rng: random.Random) -> str:
    """A document with the hard parts of TOML for a scanner: brackets, quotes, '#', '.' and '='
    inside the four kinds of string, quoted dotted keys, comments, multi-line arrays, inline tables."""
    chars = list("ab[]{}#.=,'\" \\x01")

    def string():
        body = "".join(rng.choice(chars) for _ in range(rng.randrange(10)))
        kind = rng.randrange(4)
        if kind == 0:
            return json.dumps(body)
        if kind == 1:
            return "'" + body.replace("'", "") + "'"
        if kind == 2:
            return '"""' + json.dumps(body)[1:-1] + '\n[[[ {{ """'
        return "'''" + body.replace("'", "") + "\n]]] # '''"

    def key():
        parts = [rng.choice([f"k{rng.randrange(9)}", json.dumps(f"q.[#{rng.randrange(9)}"), f"'l.]{{{rng.randrange(9)}'"])
                 for _ in range(rng.randrange(1, 4))]
        return (" . " if rng.random() < 0.3 else ".").join(parts)

    def value(depth):
        r = rng.random()
        if depth > 5 or r < 0.4:
            return rng.choice([string(), "1.5e3", "-7", "true", "1979-05-27"])
        if r < 0.7:
            items = [value(depth + 1) for _ in range(rng.randrange(4))]
            return "[" + rng.choice([", ", ",\n  # [[[\n  "]).join(items) + "]"
        items = {f"i{rng.randrange(20)}": value(depth + 1) for _ in range(rng.randrange(3))}
        return "{" + ", ".join(f"{k} = {v}" for k, v in items.items()) + "}"

    lines = []
    for t in range(rng.randrange(1, 4)):
        header = ".".join(f"h{rng.randrange(5)}{t}" for _ in range(rng.randrange(1, 4)))
        lines.append(rng.choice([f"[{header}]", f"[[{header}]]", f"[ {header} ] # [x"]))
        lines += [f"{key()} = {value(0)}  # ]]] {{" for _ in range(rng.randrange(4))]
    return "\n".join(lines) + "\n"


def test_the_scan_passes_valid_toml_and_stops_deep_nesting():
    """The scan before tomllib never refuses a valid document within the bounds (800 random ones
    with brackets and quotes in strings, keys and comments) and refuses nesting tomllib can still
    parse (21-200 levels) as well as nesting it cannot (100000)."""
    rng, parsed = random.Random(7), 0
    for _ in range(800):
        text = _random_toml(rng)
        try:
            tomllib.loads(text)
        except tomllib.TOMLDecodeError:
            continue
        parsed += 1
        assert textfile.shape_problem(text) is None, text
    assert parsed > 700
    for d in (1, 10, textfile.MAX_NESTING):
        assert textfile.shape_problem("x = " + "[" * d + "]" * d) is None
        assert textfile.shape_problem("x = " + "{a = " * d + "1" + "}" * d) is None
    for d in (textfile.MAX_NESTING + 1, 200, 100000):
        for text in ("[t]\nx = [\n" + "[" * d + "]" * d + "]", "[t]\nx = " + "{a = " * d + "1" + "}" * d):
            key, msg = textfile.shape_problem(text)
            assert key == "t.x" and "nested more than 20 deep" in msg
    key, msg = textfile.shape_problem('"q.x".b' + ".c" * 100000 + " = 1")
    assert key.startswith("q.x.b.c") and "more than 20 parts (line 1)" in msg


@pytest.mark.parametrize("doc, key, text", [
    ({"belt": {"EI": 2**63}}, "belt.EI", "an integer of 19 digits"),
    ({"belt": {"EI": -2**63 - 1}}, "belt.EI", "an integer of 19 digits"),
    ({"belt": {"EI": 10**400}}, "belt.EI", "an integer of 401 digits"),
    ({"x": [[1, 10**30]]}, "x[0][1]", "an integer of 31 digits"),
    ({"description": "d" * 10_001}, "description", "a string of 10001 characters, longer than the limit of 10000"),
    ({"pulley": [{"name": "n" * 101}]}, "pulley[0].name", "longer than the limit of 100"),
    ({"route": {"order": ["o" * 1001]}}, "route.order[0]", "longer than the limit of 1000"),
    ({"k" * 101: 1}, "k" * 40 + "...", "a key of 101 characters"),
    ({"grid": [{"values": [0] * 100_001}]}, "grid[0].values", "an array of 100001 elements"),
])
def test_values_no_key_can_carry(doc, key, text):
    def fail(k, m):
        raise BeltjaxError(m, k)

    with pytest.raises(BeltjaxError) as e:
        tomltable.check_document(doc, fail)
    assert e.value.key == key and text in str(e.value)


def test_values_within_the_bounds_pass():
    tomltable.check_document({"a": [2**63 - 1, -2**63], "description": "d" * 10_000, "name": "n" * 100,
                              "x": [[[0]]], "values": list(range(100_000))}, None)


def test_messages_quote_at_most_a_little_of_a_value():
    assert tomltable.show("x" * 10**6) == repr("x" * 40) + "... (1000000 characters)"
    assert tomltable.show(10**400) == "an integer of 401 digits"
    assert tomltable.show(-(10**5000)) == "an integer of 5001 digits"  # beyond Python's int -> str limit
    assert tomltable.show(list(range(10**5))).endswith(", ...] (100000 elements)")
    assert len(tomltable.show({"k": "v" * 1000})) < 100
    r = tomltable.Reader(lambda k, m: (_ for _ in ()).throw(BeltjaxError(m, k)))
    for call in (lambda: r.number("a", 10**400), lambda: r.integer("a", 10**400, maximum=5),
                 lambda: r.string("a", "s" * 10**6, choices=("x",)), lambda: r.vector2("a", [1.0] * 10**5)):
        with pytest.raises(BeltjaxError) as e:
            call()
        assert len(str(e.value)) < 200, str(e.value)


def test_dataset_files_inside_the_folder(tmp_path):
    """Relative names, sub-folders and links that stay inside the folder are accepted; absolute
    paths, '..' and links out of the folder are refused naming the key."""
    data = tmp_path / "data"
    (data / "sub").mkdir(parents=True)
    (data / "sub" / "x.csv").write_text("a\n")
    (tmp_path / "out.csv").write_text("a\n")
    (data / "in_link.csv").symlink_to(data / "sub" / "x.csv")
    (data / "dir_link").symlink_to(tmp_path)
    (data / "out_link.csv").symlink_to(tmp_path / "out.csv")
    assert dataset_file(data, "sub/x.csv", "k") == data.resolve() / "sub" / "x.csv"
    assert dataset_file(data, "in_link.csv", "k").read_text() == "a\n"
    for name, text in [("/etc/passwd", "is an absolute path"), ("../out.csv", "leads out of the dataset's folder"),
                       ("sub/../../out.csv", "leads out"), ("out_link.csv", "is a link to a file outside"),
                       ("dir_link/out.csv", "is a link to a file outside"), ("a\0b", "NUL character"), ("", "expected")]:
        with pytest.raises(DataError) as e:
            dataset_file(data, name, "tensile.record[0].file")
        assert str(e.value).startswith("tensile.record[0].file: ") and text in str(e.value), str(e.value)
