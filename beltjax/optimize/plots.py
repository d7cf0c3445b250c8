"""Plots of an optimisation: Campbell diagrams with the bands shaded, the loss history."""

from __future__ import annotations

import numpy as np

from beltjax.optimize.problem import Problem
from beltjax.optimize.solver import OptimizeResult


def _plot_campbell_band(result, path, title: str, problem: Problem) -> None:
    """:func:`beltjax.plotting.plot_campbell` with each resonance objective's speed band shaded and
    its order lines drawn bold inside the band."""
    from beltjax.plotting import plot_campbell

    bands = [(o.rpm[0], o.rpm[1], tuple(o.orders),
              f"band {o.rpm[0]:g}-{o.rpm[1]:g} rpm\n"
              f"orders {', '.join(f'{k:g}x' for k in o.orders)}, margin {o.margin_hz:g} Hz")
             for o in problem.objectives if o.kind == "resonance_band"]
    plot_campbell(result, path, title=title, bands=bands)


def plot_history(result: OptimizeResult, path) -> None:
    """Save the loss history (log scale) and the variables' paths (scaled to their bounds) (PNG);
    parameter paths drawn literally, paths that lie on each other dashed with a note."""
    from beltjax.plotting import coinciding, literal, overlay_style, save, subplots

    steps = [h["step"] for h in result.history]
    fig, (a1, a2) = subplots(2, 1, figsize=(9, 6.5), sharex=True)
    a1.semilogy(steps, np.maximum(result.loss_history, 1e-12), color="tab:blue", lw=1.5)
    a1.set_ylabel("loss")
    a1.grid(alpha=0.3, which="both")
    a1.set_title(f"loss {result.loss0:.4g} -> {result.loss:.4g}; {result.steps} steps, "
                 f"{result.rejected} rejected; {result.reason}", fontsize=9)
    X = np.array([h["x"] for h in result.history])
    scaled = [(X[:, j] - result.lower[j]) / (result.upper[j] - result.lower[j]) for j in range(len(result.paths))]
    names = [literal(p, 60) for p in result.paths]
    over = coinciding(scaled)
    for j, y in enumerate(scaled):
        ls, note = overlay_style(over, names, j)
        a2.plot(steps, y, lw=1.4, ls=ls, label=names[j] + note)
    a2.set_ylim(-0.05, 1.05)
    a2.set_ylabel("(x - lower) / (upper - lower)")
    a2.set_xlabel("step")
    a2.grid(alpha=0.3)
    a2.legend(fontsize=8, loc="best")
    save(fig, path, dpi=110)
