"""Every error type is raised the same way: (message, key), the message one line starting with
the key, extra context keyword-only; the command line maps them all to one line and exit 2."""

import importlib
import inspect
import pathlib

import pytest

from beltjax.errors import BeltjaxError

MODULES = ["beltjax.errors", "beltjax.scene", "beltjax.parameters", "beltjax.geometry", "beltjax.statics",
           "beltjax.sweep", "beltjax.transient", "beltjax.optimize", "identification.data"]


def _subclasses():
    for m in MODULES:
        importlib.import_module(m)
    seen, todo = [], [BeltjaxError]
    while todo:
        c = todo.pop()
        seen.append(c)
        todo.extend(c.__subclasses__())
    return seen


def test_every_error_has_the_same_signature():
    classes = _subclasses()
    names = {c.__name__ for c in classes}
    assert {"SceneError", "ParameterError", "GeometryError", "StaticsError", "SweepError", "TransientError",
            "OptimizeError", "DataError", "InputError"} <= names
    for c in classes:
        params = list(inspect.signature(c).parameters.values())
        positional = [p.name for p in params if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
        assert positional == ["message", "key"], (c.__name__, positional)
        e = c("must be > 0, got -1\n(second line)", "belt.EA")
        assert str(e) == "belt.EA: must be > 0, got -1 (second line)", c.__name__
        assert e.key == "belt.EA"
        assert isinstance(e, ValueError)


@pytest.mark.parametrize("message", ["belt.EA: already prefixed", "belt.EA"])
def test_a_key_is_not_repeated(message):
    assert str(BeltjaxError(message, "belt.EA")) == message


def test_control_characters_are_escaped_on_the_error_line(tmp_path, capsys):
    """A message that quotes bytes of a binary file (a crank trace of control characters) prints
    them as escapes, not raw NUL and control bytes on the terminal."""
    from beltjax.cli import main
    from beltjax.errors import printable

    assert printable("a\x00b\x1b[2J\u00e9") == "a\\x00b\\x1b[2J\u00e9"
    scene = (pathlib.Path(__file__).resolve().parents[1] / "scenes" / "fead_8pulley.toml").read_text()
    (tmp_path / "crank.csv").write_bytes(bytes(range(32)) + b"\n" + bytes(range(1, 32)) + b"\n")
    (tmp_path / "scene.toml").write_text(scene + '\n[[fluctuation]]\npulley = "crank"\nfile = "crank.csv"\n')
    assert main(["statics", str(tmp_path / "scene.toml"), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and all(c.isprintable() for c in err), repr(err)


@pytest.mark.parametrize("not_a_scene", ["scenes/two_pulley_T400.toml", {"belt": {}}, None])
def test_an_analysis_given_what_is_not_a_scene_raises_one_line(not_a_scene):
    """The Python API's analyses given a file name, a dict or None raise the one-line error
    naming ``scene`` (an AttributeError deep inside before)."""
    import beltjax
    from beltjax import transient

    for f in (beltjax.analyse_statics, beltjax.analyse_modes, lambda s: transient.simulate(s, 0.1),
              lambda s: beltjax.analyse_campbell(s, [0.0, 100.0])):
        with pytest.raises(beltjax.BeltjaxError, match="expected a beltjax Scene") as e:
            f(not_a_scene)
        assert e.value.key == "scene" and "\n" not in str(e.value)
