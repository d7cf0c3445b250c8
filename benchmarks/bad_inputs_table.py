"""Write the README's table of bad inputs from the robustness test's own rows.

Usage::

    python benchmarks/bad_inputs_table.py

Runs every row of ``tests/test_robustness_inputs.py`` (``CASES``: a broken copy of a shipped
file or a bad argument, each through ``beltjax.cli.main`` in this process), takes the one line
each prints on stderr, and writes ``benchmarks/results/readme/bad_inputs.md``: one markdown row
per case (input, what is wrong, the message after ``beltjax: error: ``, with the temporary
folder's path left out).  The README quotes that file between ``<!-- table: bad_inputs -->``
and ``<!-- end table -->``; ``tests/test_readme.py`` checks that it does, and that the table
has one row per case with each row's expected texts in its message.  Re-run it after adding a
row or changing a message.
"""

from __future__ import annotations

import contextlib
import io
import os
import pathlib
import sys
import tempfile

ROOT = pathlib.Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results" / "readme" / "bad_inputs.md"
PREFIX = "beltjax: error: "
MAX_MESSAGE = 160  # characters of a message shown in the table (the rest as " …")


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def message_of(case, tmp: pathlib.Path) -> str:
    """The error line of one case (after the prefix), with ``tmp`` left out of paths."""
    from beltjax.cli import main

    sys.path.insert(0, str(ROOT / "tests"))
    import test_robustness_inputs as t

    out = tmp / "out"
    argv = case.argv(tmp)
    if "--out" not in argv:
        argv = [*argv, "--out", str(out)]
    err = io.StringIO()
    cwd = os.getcwd()
    os.chdir(tmp)
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            t._with_timeout(lambda: main(argv), t.ROW_TIMEOUT_S)
    finally:
        os.chdir(cwd)
    line = err.getvalue().strip().splitlines()[-1] if err.getvalue().strip() else ""
    line = line[len(PREFIX):] if line.startswith(PREFIX) else line
    for base in (str(tmp / "data") + "/", str(tmp) + "/", str(tmp)):
        line = line.replace(base, "" if base.endswith("/") else "DIR")
    return line


def table() -> str:
    """The markdown table of every case (header included)."""
    sys.path.insert(0, str(ROOT / "tests"))
    import test_robustness_inputs as t

    rows = ["| Input | What is wrong | Error message (after `beltjax: error: `) |", "|---|---|---|"]
    for case in t.CASES:
        with tempfile.TemporaryDirectory(prefix="beltjax-bad-") as d:
            msg = message_of(case, pathlib.Path(d))
        if len(msg) > MAX_MESSAGE:
            msg = msg[:MAX_MESSAGE].rstrip() + " …"
        rows.append(f"| {_cell(case.input)} | {_cell(case.wrong)} | `{_cell(msg)}` |")
    return "\n".join(rows) + "\n"


def main() -> int:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    text = table()
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(text)
    print(f"wrote {OUT.relative_to(ROOT)} ({text.count(chr(10)) - 2} rows)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
