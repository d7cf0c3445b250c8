"""The README cannot drift: its commands run as written, its example outputs are saved runs.

* Every command line the README shows calls ``.venv/bin/beltjax`` (the set-up command never
  activates the virtual environment, so a bare ``beltjax`` is "command not found"), and every
  concrete one (no placeholder such as SCENE) parses with the real argument parser and names
  files that exist.
* Every block after a ``<!-- example: NAME -->`` marker consists of lines of
  ``benchmarks/results/readme/NAME.txt``, in order (``...`` leaves lines out); that file is
  what ``benchmarks/readme_examples.py`` saved from the README's command, so a change that
  moves a worked example shows up when the script is re-run, and here until the README
  quotes it.
* Every figure the README shows exists, and the test command is the one ``.ci/run`` runs.
"""

from __future__ import annotations

import pathlib
import re
import shlex

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
SAVED = ROOT / "benchmarks" / "results" / "readme"
COMMANDS = ("span", "statics", "modal", "campbell", "simulate", "fit", "sweep", "optimize")


def _code_lines(text: str) -> list[str]:
    """Lines inside fenced blocks and indented (4-space) blocks of the README."""
    out, fenced = [], False
    for line in text.splitlines():
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        if fenced or line.startswith("    "):
            out.append(line.strip())
    return out


def _command_lines(with_errors: bool = True) -> list[str]:
    """Command lines of the README's code blocks; ``with_errors=False`` leaves out the ones shown
    with the error they give (a ``beltjax: error:`` line right after them)."""
    pat = re.compile(r"(^|&&\s*|\$ )(\S*beltjax)\s+(" + "|".join(COMMANDS) + r")\b")
    lines = []
    code = _code_lines(README)
    for i, line in enumerate(code):
        if not with_errors and i + 1 < len(code) and code[i + 1].startswith("beltjax: error:"):
            continue
        for part in line.split("&&"):
            part = part.strip()
            if part.startswith("$ "):
                part = part[2:]
            if pat.search(part) and not part.startswith("beltjax:"):
                lines.append(part)
    return lines


def test_readme_commands_call_the_installed_script():
    lines = _command_lines()
    assert len(lines) > 10
    bare = [x for x in lines if not x.startswith(".venv/bin/beltjax ")]
    assert not bare, f"README commands that are not '.venv/bin/beltjax ...': {bare}"


def test_readme_concrete_commands_parse_and_name_existing_files():
    from beltjax.cli import build_parser

    parser = build_parser()
    checked = 0
    for line in _command_lines(with_errors=False):
        words = shlex.split(line.split("->")[0])[1:]
        if any(re.fullmatch(r"[A-Z][A-Z0-9_.]*", w) or w in ("...",) or w.startswith("[") for w in words):
            continue  # a synopsis with placeholders
        args = parser.parse_args(words)
        for name in ("scene", "spec", "data"):
            value = getattr(args, name, None)
            if value is not None:
                assert (ROOT / value).is_file(), f"{line}: {value} does not exist"
        checked += 1
    assert checked >= 8


def _example_blocks():
    blocks = []
    lines = README.splitlines()
    for i, line in enumerate(lines):
        m = re.fullmatch(r"\s*<!-- example: (\S+) -->\s*", line)
        if not m:
            continue
        j = i + 1
        while j < len(lines) and not lines[j].strip():
            j += 1
        body = []
        if lines[j].lstrip().startswith("```"):
            j += 1
            while not lines[j].lstrip().startswith("```"):
                body.append(lines[j])
                j += 1
        else:
            while j < len(lines) and (lines[j].startswith("    ") or not lines[j].strip()):
                body.append(lines[j][4:])
                j += 1
        blocks.append((m.group(1), [b.rstrip() for b in body if b.strip()]))
    return blocks


def test_readme_examples_are_saved_runs():
    blocks = _example_blocks()
    assert len(blocks) >= 6
    for name, body in blocks:
        saved = SAVED / f"{name}.txt"
        assert saved.is_file(), f"README quotes example {name!r} but {saved} is missing (run benchmarks/readme_examples.py)"
        have = [x.rstrip() for x in saved.read_text().splitlines()]
        k = 0
        for line in body:
            if line.strip() == "...":
                continue
            while k < len(have) and have[k] != line:
                k += 1
            assert k < len(have), f"README example {name!r}: line not in {saved.name} (in order): {line!r}"
            k += 1


def test_readme_figures_exist():
    figs = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", README)
    assert figs
    for f in figs:
        assert (ROOT / f).is_file(), f"README shows {f}, which does not exist"


def test_readme_test_command_is_the_ci_command():
    ci = (ROOT / ".ci" / "run").read_text().strip().splitlines()[-1]
    assert ci in README


@pytest.mark.parametrize("name", sorted(p.stem for p in SAVED.glob("*.txt")) or ["none"])
def test_saved_examples_came_from_readme_commands(name):
    """Each saved output starts with the command it came from, and the README shows that command."""
    if name == "none":
        pytest.skip("no saved examples")
    first = (SAVED / f"{name}.txt").read_text().splitlines()[0]
    assert first.startswith("$ .venv/bin/beltjax ")
    cmd = first[2:].replace(" --out out", "")
    assert cmd.split(" --out")[0] in README, f"{name}: the README does not show {cmd!r}"


def _marked_table(name: str) -> list[str]:
    lines = README.splitlines()
    start = lines.index(f"<!-- table: {name} -->")
    end = lines.index("<!-- end table -->", start)
    return [x for x in lines[start + 1:end] if x.strip()]


def test_readme_bad_input_table_is_the_saved_run_of_the_robustness_rows():
    """The README's bad-input table is benchmarks/bad_inputs_table.py's output, one row per row of
    tests/test_robustness_inputs.py, in order."""
    import sys

    saved = (SAVED / "bad_inputs.md").read_text().splitlines()
    assert _marked_table("bad_inputs") == [x for x in saved if x.strip()]
    sys.path.insert(0, str(ROOT / "tests"))
    import test_robustness_inputs as t

    rows = saved[2:]
    assert len(rows) == len(t.CASES), "re-run benchmarks/bad_inputs_table.py"
    for case, row in zip(t.CASES, rows):
        assert row.startswith(f"| {case.input.replace('|', chr(92) + '|')} |"), (case.id, row)


def test_readme_ranges_table_is_the_schema():
    """The README's table of accepted ranges is generated from beltjax.schema (one source)."""
    from beltjax import schema

    assert _marked_table("ranges") == [x for x in schema.markdown_table().splitlines() if x.strip()]
