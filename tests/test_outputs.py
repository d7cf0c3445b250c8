"""All or nothing, on a fresh line: staged output folders (beltjax.outputs) and progress lines
(beltjax.progress), through the command line in-process.

A failing command leaves --out absent (when it did not exist) or unchanged (when it did), a
successful one writes every file, and an error raised while a progress line is open starts a
line of its own.  The failing commands fail before (statics of an impossible belt) or after
(a plot function that raises) their analysis; the analyses run on the two-pulley bench with
3 elements per span (one compilation for the module).
"""

import io
import os
import pathlib
import sys

import pytest

from _scenes import scene_text, substitute
from beltjax import outputs, progress
from beltjax.cli import main
from beltjax.errors import BeltjaxError

SMALL = ("elements_per_span = 16", "elements_per_span = 3")


@pytest.fixture(autouse=True)
def _cache(tmp_path_factory, monkeypatch):
    """The commands' persistent JAX cache in a temporary folder, not the user's home."""
    monkeypatch.setenv("BELTJAX_CACHE", str(tmp_path_factory.getbasetemp() / "jax_cache"))
    monkeypatch.delenv("BELTJAX_DEBUG", raising=False)


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """The T = 200 N two-pulley bench with 3 elements per span."""
    p = tmp_path_factory.mktemp("scene") / "small.toml"
    p.write_text(substitute(scene_text("two_pulley_T200.toml"), SMALL))
    return p


@pytest.fixture(scope="module")
def short_belt(tmp_path_factory):
    """A belt 1.60 m long on the bench's fixed centres: no static state (a StaticsError)."""
    p = tmp_path_factory.mktemp("scene") / "short.toml"
    p.write_text(substitute(scene_text("two_pulley_T200.toml"), SMALL,
                            ("static_tension = 200.0", "length = 1.60")))
    return p


def _snapshot(folder: pathlib.Path) -> dict:
    return {p.relative_to(folder): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def _no_staging_left(parent: pathlib.Path):
    left = [p.name for p in parent.iterdir() if p.name.startswith(".beltjax-staging-")]
    assert not left, left


def _existing_out(tmp_path) -> pathlib.Path:
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("the engineer's notes")
    (out / "statics.json").write_text('{"old": true}')
    return out


# --------------------------------------------------------------------------- failing commands


def test_failing_analysis_leaves_no_out_folder(short_belt, tmp_path, capsys):
    out = tmp_path / "new" / "out"
    assert main(["statics", str(short_belt), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("beltjax: error: belt.length") and err.count("\n") == 1, err
    assert not (tmp_path / "new").exists()  # neither --out nor its missing parent
    _no_staging_left(tmp_path)


def test_failing_analysis_leaves_existing_out_unchanged(short_belt, tmp_path, capsys):
    out = _existing_out(tmp_path)
    before = _snapshot(out)
    assert main(["statics", str(short_belt), "--out", str(out)]) == 2
    assert _snapshot(out) == before
    _no_staging_left(tmp_path)
    _no_staging_left(out)


@pytest.mark.parametrize("existing", [False, True], ids=["new-out", "existing-out"])
def test_failure_while_plotting_writes_nothing(small, tmp_path, capsys, monkeypatch, existing):
    """statics.json is written before layout.png: a plot that fails must not leave it behind."""
    from beltjax import plotting

    def broken(*args, **kwargs):
        raise RuntimeError("the plot failed")

    monkeypatch.setattr(plotting, "plot_layout", broken)
    out = _existing_out(tmp_path) if existing else tmp_path / "out"
    before = _snapshot(out) if existing else None
    assert main(["statics", str(small), "--out", str(out)]) == 1
    captured = capsys.readouterr()
    assert captured.err == "beltjax: error: the plot failed\n"
    assert "wrote" not in captured.out
    if existing:
        assert _snapshot(out) == before
    else:
        assert not out.exists()
    _no_staging_left(tmp_path)


def test_success_writes_every_file_and_keeps_others(small, tmp_path, capsys):
    out = _existing_out(tmp_path)
    assert main(["statics", str(small), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert (out / "keep.txt").read_text() == "the engineer's notes"  # other files left alone
    assert '"old"' not in (out / "statics.json").read_text()  # same name: replaced
    assert (out / "layout.png").stat().st_size > 10_000
    assert sorted(p.name for p in out.iterdir()) == ["keep.txt", "layout.png", "statics.json"]
    # the final paths, printed after the move
    assert printed.rstrip().endswith(f"wrote {out / 'statics.json'} and {out / 'layout.png'}")
    _no_staging_left(tmp_path)


# --------------------------------------------------------------------------- the stage itself


def test_stage_moves_files_only_on_success(tmp_path):
    target = tmp_path / "a" / "b"
    with outputs.staged(target) as stage:
        folder = stage.folder()
        assert folder.parent == tmp_path and not target.exists()  # next to the target, same file system
        (folder / "x.txt").write_text("x")
        (folder / "y.txt").write_text("y")
    assert sorted(p.name for p in target.iterdir()) == ["x.txt", "y.txt"]
    assert stage.written == [target / "x.txt", target / "y.txt"]
    with pytest.raises(KeyError):
        with outputs.staged(tmp_path / "c") as stage:
            (stage.folder() / "z.txt").write_text("z")
            raise KeyError("interrupted")
    assert not (tmp_path / "c").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a"]


def test_stage_puts_the_target_back_when_a_move_fails(tmp_path):
    """A file whose name is taken by a folder in --out: the commit fails and undoes its moves."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "a.txt").write_text("old a")
    (out / "b.txt").mkdir()
    with pytest.raises(BeltjaxError, match=r"^--out: cannot create directory .*b\.txt"):
        with outputs.staged(out) as stage:
            (stage.folder() / "a.txt").write_text("new a")
            os.utime(stage.folder() / "a.txt", ns=(1, 1))  # moved first
            (stage.folder() / "b.txt").write_text("new b")
    assert (out / "a.txt").read_text() == "old a" and (out / "b.txt").is_dir()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


@pytest.mark.parametrize("make", [lambda d: d / "taken", lambda d: d / "taken" / "sub"], ids=["file", "below-file"])
def test_out_that_is_a_file(tmp_path, make):
    (tmp_path / "taken").write_text("x")
    with pytest.raises(BeltjaxError, match=r"^--out: cannot create directory"):
        with outputs.staged(make(tmp_path)) as stage:
            stage.folder()
    assert (tmp_path / "taken").read_text() == "x"


def test_library_functions_report_only_outside_a_stage(tmp_path, capsys):
    outputs.wrote([tmp_path / "a.csv", tmp_path / "b.png"])
    assert capsys.readouterr().out == f"wrote {tmp_path / 'a.csv'} and {tmp_path / 'b.png'}\n"
    with outputs.staged(tmp_path / "o"):
        outputs.wrote([tmp_path / "a.csv"])
    assert capsys.readouterr().out == ""


# --------------------------------------------------------------------------- progress lines


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def _fake_campbell(steps_done):
    def analyse(scene, rpm, orders=None, n_modes=20, progress=None):
        for k in steps_done:
            progress(k, 4)
        raise BeltjaxError("belt.EI: failed half way", "belt.EI")

    return analyse


@pytest.mark.parametrize("tty", [True, False], ids=["terminal", "pipe"])
def test_error_during_progress_starts_its_own_line(small, tmp_path, monkeypatch, tty):
    from beltjax import campbell

    err = _Terminal() if tty else io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    monkeypatch.setattr(campbell, "analyse_campbell", _fake_campbell([1, 2]))
    out = tmp_path / "out"
    assert main(["campbell", str(small), "--rpm", "0:300:100", "--out", str(out)]) == 2
    text = err.getvalue()
    assert text.endswith("\nbeltjax: error: belt.EI: failed half way\n"), repr(text)
    assert "campbell: 1/4 speeds" in text
    assert progress.line_open() is False
    if tty:
        assert text.startswith("\rcampbell: 1/4 speeds")  # drawn in place, left open, then ended
    else:
        assert "\r" not in text and text.splitlines()[0].startswith("campbell: 1/4 speeds")
    assert not out.exists()


def test_reporter_on_a_pipe_prints_whole_lines(monkeypatch):
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    show = progress.counter("  sweep", "cases")
    for k in range(1, 6):
        show(k, 5)
    lines = err.getvalue().split("\n")
    # the first update, then none within LOG_INTERVAL_S, and always the last
    assert len(lines) == 3 and lines[-1] == "", lines
    assert "1/5 cases" in lines[0] and "5/5 cases" in lines[1] and "\r" not in err.getvalue()
    assert not progress.line_open()


def test_reporter_on_a_terminal_redraws_one_line(monkeypatch):
    err = _Terminal()
    monkeypatch.setattr(sys, "stderr", err)
    rep = progress.Reporter(tty_interval_s=0.0)
    rep.update("step 10 of 100, a long text")
    assert progress.line_open()
    rep.update("step 20")  # shorter: padded over the longer one
    progress.message("a warning")  # ends the open line first
    assert err.getvalue() == "\rstep 10 of 100, a long text\rstep 20" + " " * 20 + "\na warning\n"
    assert not progress.line_open()
    rep.update("step 30")
    rep.finish()
    assert err.getvalue().endswith("\rstep 30\n")
