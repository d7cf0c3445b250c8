"""Figures of a response over speed, small multiples for an engineer's glance: order content
against speed as colour maps, min/mean/max envelopes, slip margins and hub-load loci."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from beltjax.plotting import colormap, literal, literal_wrapped, save, subplots

#: speeds drawn in the hub-load loci
LOCI_SPEEDS = 5
#: a span node whose transverse displacement stays below this (m) is drawn flat and titled "still"
STILL_M = 1e-9


def _panels(result) -> list[tuple[str, int | None, str]]:
    """(channel, column or None, panel title) of the arm and every span."""
    out = []
    if "arm_angle_deg:mean" in result.stats:
        out.append(("arm_angle_deg", None, "tensioner arm angle"))
    for j, name in enumerate(result.columns.get("span_tensions_N", [])):
        out.append(("span_tensions_N", j, f"span {name} tension"))
    return out


def _span_panels(result) -> list[tuple[str, int | None, str]]:
    """(channel, column, panel title) of each recorded span node's transverse displacement (the
    hybrid model's; by default each span's middle node)."""
    return [("node_displacements_m", j, f"span {name} transverse")
            for j, name in enumerate(result.columns.get("node_displacements_m", []))]


def _grid(n: int, ncols: int = 3):
    ncols = min(ncols, n)
    nrows = math.ceil(n / ncols)
    return nrows, ncols


def _series(result, channel, col, stat):
    x = result.channel(channel, stat)
    return x if col is None else x[:, col]


def _mark_flagged(ax, result) -> None:
    """Shade the speeds whose status is not ok."""
    bad = np.asarray([s != "ok" for s in result.status])
    if not bad.any():
        return
    rpm = result.rpm
    half = np.diff(rpm).min() / 2 if rpm.size > 1 else 50.0
    for r in rpm[bad]:
        ax.axvspan(r - half, r + half, color="0.85", lw=0, zorder=0)


def _finish(fig, axes, used: int, title: str, path) -> None:
    for ax in axes[used:]:
        ax.set_visible(False)
    if title:
        fig.suptitle(literal_wrapped(title, 110), fontsize=10)
    save(fig, path, top_in=0.45 if title else None)


def plot_order_maps(result, path, *, title: str = "", panels=None) -> None:
    """Order amplitude (colour, channel units) against speed (rpm) and crank order, one panel per
    channel (arm angle, each span tension; or ``panels``)."""
    panels = _panels(result) if panels is None else panels
    nrows, ncols = _grid(len(panels))
    fig, axes = subplots(nrows, ncols, figsize=(4.2 * ncols, 2.8 * nrows), squeeze=False)
    axes = axes.ravel()
    orders = np.asarray(result.orders)
    rpm = result.rpm
    for ax, (ch, col, name) in zip(axes, panels):
        amp = _series(result, ch, col, "orders")  # (S, H)
        if rpm.size > 1:
            m = ax.pcolormesh(rpm, orders, amp.T, shading="nearest", cmap="viridis")
            fig.colorbar(m, ax=ax, label=f"amplitude [{result.units[ch]}]")
        else:
            ax.bar(orders, amp[0], width=0.3 / max(1, result.meta["revolutions_per_cycle"]))
        ax.set_title(literal(name), fontsize=9)
        ax.set_xlabel("crank speed [rpm]")
        ax.set_ylabel("crank order")
    _finish(fig, axes, len(panels), title, path)


def plot_envelopes(result, path, *, title: str = "", panels=None) -> None:
    """Min, mean and max over the cycle against speed (rpm), one panel per channel (arm angle,
    each span tension; or ``panels``); speeds whose status is not ok are shaded."""
    panels = _panels(result) if panels is None else panels
    nrows, ncols = _grid(len(panels))
    fig, axes = subplots(nrows, ncols, figsize=(4.2 * ncols, 2.6 * nrows), squeeze=False)
    axes = axes.ravel()
    for ax, (ch, col, name) in zip(axes, panels):
        lo, mean, hi = (_series(result, ch, col, s) for s in ("min", "mean", "max"))
        _mark_flagged(ax, result)
        ax.fill_between(result.rpm, lo, hi, color="C0", alpha=0.3, lw=0, label="min-max")
        ax.plot(result.rpm, mean, color="C0", lw=1.2, label="mean")
        if ch == "span_tensions_N":
            ax.axhline(0.0, color="k", lw=0.6)
        if ch == "node_displacements_m" and np.nanmax(np.abs(np.concatenate([lo, hi])), initial=0.0) < STILL_M:
            ax.set_ylim(-1e-3, 1e-3)  # a straight span (round-off only): drawn flat on a millimetre scale
            name = f"{name}, still"
        ax.set_title(literal(name), fontsize=9)
        ax.set_xlabel("crank speed [rpm]")
        ax.set_ylabel(f"[{result.units[ch]}]")
    if panels:
        axes[0].legend(fontsize=7, loc="best")
    _finish(fig, axes, len(panels), title, path)


def plot_slip_margins(result, path, *, title: str = "") -> bool:
    """The least slip margin over the cycle (-) of each arc with a friction coefficient against
    speed; below 0 the arc would slip.  False (nothing drawn) without such arcs."""
    if "min_slip_margin" not in result.stats:
        return False
    names = result.columns["min_slip_margin"]
    nrows, ncols = _grid(len(names), 4)
    fig, axes = subplots(nrows, ncols, figsize=(3.3 * ncols, 2.3 * nrows), squeeze=False, sharey=True)
    axes = axes.ravel()
    m = result.stats["min_slip_margin"]
    for j, (ax, name) in enumerate(zip(axes, names)):
        _mark_flagged(ax, result)
        ax.plot(result.rpm, np.clip(m[:, j], -1.0, 1.0), color="C3", lw=1.2)
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_ylim(-1.05, 1.05)
        ax.set_title(literal(name), fontsize=9)
        ax.set_xlabel("crank speed [rpm]")
        if j % ncols == 0:
            ax.set_ylabel("least slip margin [-]")
    _finish(fig, axes, len(names), title or "least slip margin over the cycle (clipped to [-1, 1])", path)
    return True


def plot_hub_loci(result, path, *, title: str = "") -> None:
    """Each bearing's hub force vector over one cycle (N, x right, y up) at up to
    :data:`LOCI_SPEEDS` speeds spread over the range, one panel per bearing."""
    names = result.columns["hub_forces_N"]
    F = result.stats["hub_forces_N"]  # (S, K, nb, 2)
    pick = np.unique(np.linspace(0, result.rpm.size - 1, min(LOCI_SPEEDS, result.rpm.size)).round().astype(int))
    nrows, ncols = _grid(len(names), 3)
    fig, axes = subplots(nrows, ncols, figsize=(3.4 * ncols, 3.2 * nrows), squeeze=False)
    axes = axes.ravel()
    color = colormap(len(pick))
    for b, (ax, name) in enumerate(zip(axes, names)):
        for j, s in enumerate(pick):
            x, y = F[s, :, b, 0], F[s, :, b, 1]
            ax.plot(np.append(x, x[0]), np.append(y, y[0]), color=color(j), lw=1.0,
                    label=f"{result.rpm[s]:.0f} rpm")
        ax.plot(0.0, 0.0, "k+", ms=6)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(literal(name), fontsize=9)
        ax.set_xlabel("Fx [N]")
        ax.set_ylabel("Fy [N]")
    axes[0].legend(fontsize=7, loc="best")
    _finish(fig, axes, len(names), title or "hub force on each bearing over one cycle", path)


def plot_all(result, out: Path, *, title: str = "") -> list[Path]:
    """Write order_maps.png, envelopes.png, slip_margins.png (with friction coefficients),
    hub_loci.png and, for the hybrid model, span_vibration_maps.png and span_vibration.png (each
    span's middle transverse displacement) to ``out``; returns their paths."""
    out = Path(out)
    paths = [out / "order_maps.png", out / "envelopes.png"]
    plot_order_maps(result, paths[0], title=title)
    plot_envelopes(result, paths[1], title=title)
    spans = _span_panels(result)
    if spans:
        paths += [out / "span_vibration_maps.png", out / "span_vibration.png"]
        plot_order_maps(result, paths[-2], title=title, panels=spans)
        plot_envelopes(result, paths[-1], title=title, panels=spans)
    if plot_slip_margins(result, out / "slip_margins.png"):
        paths.append(out / "slip_margins.png")
    plot_hub_loci(result, out / "hub_loci.png")
    paths.append(out / "hub_loci.png")
    return paths
