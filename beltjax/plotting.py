"""Figures: mode shapes of a span (matplotlib, written to files, no screen needed)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from beltjax import ancf  # noqa: E402
from beltjax.span import element_index  # noqa: E402


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
    fig, (ax, axl) = plt.subplots(2, 1, figsize=(8, 6), sharex=True, height_ratios=[3, 1.4])
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
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
