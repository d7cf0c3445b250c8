"""Figures written to PNG files: the shared figure helpers and span mode shapes (a drive's layout,
mode shapes and Campbell diagram: :mod:`beltjax.plot_drive`; time histories and spectra of
simulations: :mod:`beltjax.plot_transient`; both re-exported here).

Figures are matplotlib ``Figure`` objects saved directly: no pyplot, no backend switched, no
global setting (rcParams) changed, so importing beltjax leaves a notebook's or an
application's matplotlib as it was.  Every piece of user text (pulley, span and mode names,
descriptions, file names, parameter paths, dataset labels) enters a figure through
:func:`literal` and is drawn as written, never read as mathtext.
"""

from __future__ import annotations

import logging
import textwrap
import unicodedata
import warnings

import matplotlib
import numpy as np
from matplotlib.figure import Figure

from beltjax import ancf
from beltjax.span import element_index

# a matplotlib without its mathtext fonts (some trimmed installs) falls back to DejaVu Sans for
# log-axis ticks and offsets, and says so once per glyph set on stderr: not the user's concern
logging.getLogger("matplotlib.font_manager").setLevel(logging.ERROR)

#: most mode-shape panels in one modes.png (a larger --modes is cut to this, with a note)
MAX_MODE_PANELS = 24


# --------------------------------------------------------------------------- text and figures


def literal(text, limit: int | None = None) -> str:
    """``text`` (any object, as ``str``) made safe to draw as written.

    Every ``$`` is escaped (matplotlib would read the text between two of them as mathtext
    and fail on ``$x^$``), control characters other than newline and tab are shown as
    ``\\xNN``, a leading ``_`` is kept visible in legends (matplotlib hides labels that
    start with one), and text longer than ``limit`` characters is shortened in the middle
    with ``...``.  Backslashes, ``%``, braces and non-ASCII characters need nothing.
    """
    s = str(text)
    if any(unicodedata.category(c) == "Cc" and c not in "\n\t" for c in s):
        s = "".join(f"\\x{ord(c):02x}" if unicodedata.category(c) == "Cc" and c not in "\n\t" else c for c in s)
    if limit is not None and len(s) > limit:
        keep = max(limit - 3, 2)
        s = s[: (keep + 1) // 2] + "..." + s[len(s) - keep // 2:]
    s = s.replace("$", r"\$")
    return " " + s if s.startswith("_") else s


def literal_wrapped(text, width: int = 80, max_lines: int | None = 4) -> str:
    """User text wrapped at ``width`` characters (newlines joined first) on at most ``max_lines``
    lines (the last one ending in "..." when cut; None: all), then :func:`literal`."""
    if not text:
        return ""
    s = str(text)
    if max_lines is not None:  # words longer than the width are broken by wrap(): bound them first
        s = s[: width * max_lines + 1]
    return literal("\n".join(textwrap.wrap(s, width, max_lines=max_lines, placeholder=" ...")))


def subplots(nrows: int = 1, ncols: int = 1, *, figsize, **kwargs):
    """``(Figure, axes)`` as ``pyplot.subplots`` gives them, without pyplot (nothing global)."""
    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, **kwargs)


def save(fig, path, dpi: int = 110, top_in: float | None = None) -> None:
    """Lay ``fig`` out (tight) and write it to ``path`` (PNG).  A character the font lacks
    (e.g. CJK in DejaVu Sans) is drawn as a box without a warning per glyph.  top_in: room (in)
    kept above the axes for a figure title (default: tight_layout's own)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Glyph .* missing from", category=UserWarning)
        warnings.filterwarnings("ignore", message="Tight layout not applied", category=UserWarning)
        if top_in is None:
            fig.tight_layout()
        else:
            fig.tight_layout(rect=(0.0, 0.0, 1.0, 1.0 - top_in / fig.get_figheight()))
        fig.savefig(path, dpi=dpi)


def colormap(n_lines: int):
    """Colour of line j among n_lines (tab10, tab20 beyond 10 lines, cycled)."""
    cmap = matplotlib.colormaps["tab20" if n_lines > 10 else "tab10"]
    return lambda j: cmap(j % cmap.N)


#: dash patterns of the curves drawn over an earlier one they coincide with
_OVER = ((0, (5, 4)), (0, (1.5, 2.5)), (0, (7, 3, 1.5, 3)), (0, (3, 5)))


def coinciding(series, rtol: float = 3e-3) -> list[int | None]:
    """For each of several curves (arrays of one shape), the index of an earlier curve it lies
    on everywhere (within ``rtol`` of the range of all of them: less than a pixel apart in a
    panel of ordinary size), else None.  Such curves are drawn dashed over the first one, with
    a note in their legend entry (:func:`overlay_style`), so that neither hides the other."""
    ys = [np.asarray(y, dtype=float) for y in series]
    values = [y[np.isfinite(y)] for y in ys]
    finite = np.concatenate(values) if values else np.zeros(0)
    if finite.size == 0:
        return [None] * len(ys)
    scale = max(float(np.ptp(finite)), 1e-12 * float(np.max(np.abs(finite))), 1e-300)
    out: list[int | None] = []
    for j, y in enumerate(ys):
        hit = None
        for i in range(j):
            x = ys[i]
            if out[i] is not None or x.shape != y.shape or not np.any(np.isfinite(y)):
                continue
            fin = np.isfinite(x)
            if np.array_equal(fin, np.isfinite(y)) and np.all(np.abs(x[fin] - y[fin]) <= rtol * scale):
                hit = i
                break
        out.append(hit)
    return out


def overlay_style(over: list[int | None], labels, j: int) -> tuple[object, str]:
    """(line style, legend note) of curve j given :func:`coinciding`'s answer: solid and no
    note, or a dash pattern and `` (on <first curve's label>)``."""
    i = over[j]
    if i is None:
        return "-", ""
    k = sum(1 for o in over[:j] if o is not None)
    return _OVER[k % len(_OVER)], f" (on {labels[i]})"


def span_field(coords, n_elements: int, L0: float, samples: int = 9):
    """Positions (or displacements) r(x) of a span's centre line from its coordinates.

    coords: (4 (N+1),) span coordinates; L0: element reference length (m).
    Returns (s, r): reference arc length (m) and r, shape (N*samples+1, 2).
    """
    idx = element_index(n_elements)
    xi = np.linspace(0.0, 1.0, samples + 1)[:-1]
    s, r = [], []
    for k in range(n_elements):
        e = np.asarray(coords)[idx[k]]
        for x in xi:
            s.append((k + x) * L0)
            r.append(np.asarray(ancf.position(e, x, L0)))
    s.append(n_elements * L0)
    r.append(np.asarray(ancf.position(np.asarray(coords)[idx[-1]], 1.0, L0)))
    return np.array(s), np.array(r)


def plot_span_modes(result, path, n_modes: int = 6):
    """Save the first transverse modes and the first longitudinal mode of a SpanResult (PNG)."""
    labels = result.labels
    picks = [i for i, lab in enumerate(labels) if lab.endswith("transverse")][: max(n_modes - 1, 1)]
    picks += [i for i, lab in enumerate(labels) if lab.endswith("longitudinal")][:1]
    fig, (ax, axl) = subplots(2, 1, figsize=(8, 6), sharex=True, height_ratios=[3, 1.4])
    if not result.stable:
        ax.text(0.5, 0.5, "unstable: past the critical speed\nno natural frequencies", ha="center",
                va="center", transform=ax.transAxes, fontsize=13, color="crimson")
    for i in picks:
        s, d = span_field(result.mode_shapes[:, i], result.n_elements, result.element_length)
        transverse = labels[i].endswith("transverse")
        comp = d[:, 1] if transverse else d[:, 0]
        comp = comp / max(np.max(np.abs(comp)), 1e-300)
        (ax if transverse else axl).plot(s * result.stretch, comp, label=f"{labels[i]}  {result.frequencies_hz[i]:.1f} Hz")
    ax.set_ylabel("transverse (y), normalised")
    axl.set_ylabel("longitudinal (x)")
    axl.set_xlabel("position along the span [m]")
    ax.set_title(f"span L = {result.length:g} m, T = {result.tension:g} N, c = {result.speed:g} m/s, "
                 f"{result.n_elements} elements, {result.bc[0]}-{result.bc[1]}")
    for a in (ax, axl):
        a.axhline(0, color="k", lw=0.5)
        if a.lines[1:]:
            a.legend(fontsize=8, loc="upper right")
    save(fig, path, dpi=120)


#: figures that live in their own modules (which import this one), re-exported on first use
_ELSEWHERE = {"plot_simulation": "plot_transient", "plot_spectra": "plot_transient", "_channel_unit": "plot_transient",
              **{n: "plot_drive" for n in ("plot_layout", "plot_drive_modes", "plot_campbell", "flexible_modes",
                                           "mode_panels", "span_curve")}}


def __getattr__(name):
    if name in _ELSEWHERE:
        import importlib

        return getattr(importlib.import_module(f"beltjax.{_ELSEWHERE[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
