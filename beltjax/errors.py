"""One error type for everything a user can get wrong or ask that cannot be done.

Every input problem, from a scene file, a sweep or optimisation file, a dataset, a
Python API argument or a parameter changed with :mod:`beltjax.parameters`, raises a
:class:`BeltjaxError` (a ``ValueError``) whose message is one line that starts with the
key or file it is about, e.g. ``belt.EI: must lie in [0, 100] N m^2, got 1e+20``.
The command line prints exactly that line after ``beltjax: error:`` and exits with
status 2; the Python API raises the same message.  The subclasses only say where the
problem was found (scene, statics, sweep, ...), so ``except BeltjaxError`` catches
them all.  Every one is raised the same way, ``XError(message, key)``; what a subclass
adds (a scene's file, a layout fault's kind and pulleys) is keyword-only.
"""

from __future__ import annotations


def one_line(message) -> str:
    """``message`` with every run of whitespace (newlines included) made one space."""
    return " ".join(str(message).split())


def printable(text: str) -> str:
    """``text`` with each character a terminal would not print as itself (control bytes of a
    binary file quoted back, say) written as its escape, ``\\x00``."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


class BeltjaxError(ValueError):
    """Bad input or an impossible request: a one-line message naming the key or cause.

    key: the key path, argument or file the message is about ("" when it names a cause);
    the message starts with it.
    """

    def __init__(self, message: str = "", key: str = ""):
        msg = one_line(message)
        if key and not (msg == str(key) or msg.startswith(f"{key}:") or msg.startswith(f"{key} ")):
            msg = f"{key}: {msg}" if msg else str(key)
        super().__init__(msg)
        self.key = key


class InputError(BeltjaxError):
    """A bad command-line argument (argparse's errors and the checks of ``beltjax.cli``)."""
