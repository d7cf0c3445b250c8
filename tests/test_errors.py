"""Every error type is raised the same way: (message, key), the message one line starting with
the key, extra context keyword-only; the command line maps them all to one line and exit 2."""

import importlib
import inspect

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
