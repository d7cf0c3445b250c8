"""Progress lines on stderr: one reporter for every long command.

On a terminal a :class:`Reporter` redraws one line in place (carriage return, at most
``TTY_INTERVAL_S`` apart) and leaves it open until its last update; on anything else
(a file, a pipe, a CI log) it prints whole lines, at most one every ``LOG_INTERVAL_S``
seconds plus the last one, and never a carriage return.  The module knows whether a
progress line is open: :func:`end_line` ends it (the command line's error handler calls
it, so that ``beltjax: error: ...`` always starts its own line) and :func:`message` prints
a line of text after ending it.
"""

from __future__ import annotations

import sys
import time

#: shortest time between two redraws of a progress line on a terminal (s)
TTY_INTERVAL_S = 0.25
#: shortest time between two progress lines written to a file or pipe (s)
LOG_INTERVAL_S = 5.0
#: characters of a progress bar
BAR_WIDTH = 30

_open = None  # the stream on which a progress line is open (no newline yet), or None


def _is_tty(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):  # a closed or unusual stream
        return False


def line_open() -> bool:
    """True while a progress line is drawn on stderr and not yet ended."""
    return _open is not None


def end_line() -> None:
    """End an open progress line (write its newline); nothing when none is open."""
    global _open
    stream, _open = _open, None
    if stream is not None:
        try:
            stream.write("\n")
            stream.flush()
        except (ValueError, OSError):  # stderr closed under us: nothing to end
            pass


def message(text: str) -> None:
    """Print ``text`` as a line of its own on stderr (ending an open progress line first)."""
    end_line()
    print(text, file=sys.stderr, flush=True)


def bar(fraction: float, width: int = BAR_WIDTH) -> str:
    """``[####      ]``: a bar ``width`` characters wide filled to ``fraction`` (clipped to [0, 1])."""
    f = min(max(float(fraction), 0.0), 1.0) if fraction == fraction else 0.0
    return "[" + ("#" * int(width * f)).ljust(width) + "]"


class Reporter:
    """One progress display on stderr (see the module docstring).

    ``update(text)`` shows the current state (skipped when the previous one is too recent),
    ``update(text, final=True)`` always shows it and ends the line; ``finish()`` shows the
    last text given if it was skipped, and ends the line.
    """

    def __init__(self, tty_interval_s: float = TTY_INTERVAL_S, log_interval_s: float = LOG_INTERVAL_S):
        self.tty_interval_s = tty_interval_s
        self.log_interval_s = log_interval_s
        self._last_shown = -float("inf")
        self._width = 0  # characters of the line drawn last (a shorter one is padded over it)
        self._pending: str | None = None  # the last text given and not shown
        self._finished = False

    def update(self, text: str, final: bool = False) -> None:
        """Show ``text`` (one line, no newline characters) as the current progress."""
        global _open
        text = " ".join(str(text).split("\n"))
        stream = sys.stderr
        tty = _is_tty(stream)
        now = time.perf_counter()
        interval = self.tty_interval_s if tty else self.log_interval_s
        if not final and now - self._last_shown < interval:
            self._pending = text
            return
        self._last_shown, self._pending = now, None
        if _open is not None and _open is not stream:  # another stream's line (stderr replaced): end it
            end_line()
        if tty:
            pad = " " * max(0, self._width - len(text))
            stream.write("\r" + text + pad + ("\n" if final else ""))
            self._width = 0 if final else len(text)
            _open = None if final else stream
        else:
            if _open is stream:
                end_line()
            stream.write(text + "\n")
        stream.flush()
        self._finished = final

    def finish(self) -> None:
        """Show the last skipped update, if any, and end the progress line."""
        if self._pending is not None:
            self.update(self._pending, final=True)
        elif not self._finished:
            end_line()
            self._finished = True


def counter(label: str, unit: str, with_bar: bool = True):
    """A ``progress(done, total)`` callback drawing ``label [###   ] done/total unit (elapsed s)``;
    the update with ``done >= total`` is always shown and ends the line."""
    rep = Reporter()
    t0 = time.perf_counter()

    def show(done: int, total: int) -> None:
        el = time.perf_counter() - t0
        head = f"{label} {bar(done / max(total, 1))} " if with_bar else f"{label}: "
        rep.update(f"{head}{done}/{total} {unit} ({el:6.1f} s)", final=done >= total)

    show.reporter = rep
    return show
