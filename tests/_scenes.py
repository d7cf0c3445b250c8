"""Shared test helpers: the example scene files as text, and edits of that text."""

import pathlib

SCENES = pathlib.Path(__file__).resolve().parents[1] / "scenes"


def scene_text(name):
    """The text of the example scene file ``scenes/<name>``."""
    return (SCENES / name).read_text()


def substitute(text, *pairs):
    """Replace each (old, new) in text; every old string must occur exactly once."""
    for old, new in pairs:
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    return text
