"""Figures of transient simulations: stacked time histories and amplitude spectra (PNG).

Split from :mod:`beltjax.plotting` (which re-exports both functions); the same rules: Figure
objects, nothing global, and channel column names (span, pulley and node names) drawn
through :func:`beltjax.plotting.literal`.  Curves that coincide (e.g. the hub-force
magnitudes of the two pulleys of a two-pulley drive) are drawn dashed over the first one,
with a note in the legend.
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from beltjax import plotting

from beltjax.plotting import colormap, coinciding, literal, literal_wrapped, overlay_style, subplots

# channel -> (panel label, default unit, factor to the plotted unit, plotted unit), in the preferred order
_SIM_CHANNELS = {
    "span_tensions_N": ("span tension", "N", 1.0, None),
    "span_forces_N": ("span force", "N", 1.0, None),
    "hub_force_magnitudes_N": ("hub force magnitude", "N", 1.0, None),
    "pulley_speeds_rpm": ("pulley speed", "rpm", 1.0, None),
    "arm_angle_deg": ("tensioner arm angle", "deg", 1.0, None),
    "spring_moment_Nm": ("tensioner spring moment", "N m", 1.0, None),
    "pivot_friction_moment_Nm": ("tensioner friction moment", "N m", 1.0, None),
    "drive_torques_Nm": ("drive torque", "N m", 1.0, None),
    "node_displacements_m": ("node displacement", "m", 1e3, "mm"),
    "slip_margins": ("slip margin (capstan law)", "-", 1.0, None),
    "slip_speeds_m_s": ("gross slip speed", "m/s", 1.0, None),
    "friction_power_W": ("belt friction power", "W", 1.0, None),
}
_SPECTRUM_CHANNELS = ("hub_forces_N", "span_tensions_N", "node_displacements_m")
_MAX_POINTS = 20000


def _channel_unit(name, units, default):
    """The unit of a channel (units[name] if given) and the factor and unit it is plotted in."""
    unit = (units or {}).get(name) or default
    scale, shown = 1.0, unit
    if name in _SIM_CHANNELS:
        _, dflt, factor, conv = _SIM_CHANNELS[name]
        if conv is not None and unit == dflt:
            scale, shown = factor, conv
    return unit, scale, shown


def _channel_lines(name, values, columns):
    """[(label, series (nt,), colour index, line style)] of a channel (nt,), (nt, k) or (nt, k, 2)."""
    from beltjax.signals import column_labels

    arr = np.asarray(values, dtype=float)
    labels = column_labels(name, arr.shape, columns)
    flat = arr.reshape(arr.shape[0], -1)
    if arr.ndim == 3:
        return [(lab, flat[:, j], j // 2, "-" if j % 2 == 0 else "--") for j, lab in enumerate(labels)]
    return [(lab, flat[:, j], j, "-") for j, lab in enumerate(labels)]


def _draw(ax, x, lines, lw):
    """Plot [(label, y, colour index, style)] against x (one array, or one per line) with literal
    labels; a line lying on an earlier one (:func:`beltjax.plotting.coinciding`) is drawn dashed
    over it and says so in the legend."""
    xs = x if isinstance(x, list) else [x] * len(lines)
    colour = colormap(max([c for _, _, c, _ in lines] + [0]) + 1)
    labels = [literal(lab, 50) for lab, _, _, _ in lines]
    over = coinciding([y for _, y, _, _ in lines])
    for j, (_, y, c, ls) in enumerate(lines):
        style, note = overlay_style(over, labels, j)
        ax.plot(xs[j], y, lw=lw, ls=ls if over[j] is None else style, color=colour(c), label=labels[j] + note)


def _legend(ax, n):
    if n > 1:
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0,
                  ncol=1 + (n - 1) // 16, handlelength=1.8)


#: a channel with more lines than this is drawn as small multiples, one panel per line
MAX_OVERLAID = 4
#: small panels per row
_SMALL_PER_ROW = 4


def plot_simulation(t, channels, columns, units, path, *, title=""):
    """Save stacked time histories of a transient simulation (PNG), one panel per channel.

    t: sample times (s), shape (nt,); channels: name -> array (nt,), (nt, k) or (nt, k, 2)
    (x solid, y dashed); columns: name -> column labels (span, pulley or node names);
    units: name -> unit string (defaults from the channel name).  Panels, in this order,
    for the channels present: span_tensions_N, span_forces_N, hub_force_magnitudes_N,
    pulley_speeds_rpm, arm_angle_deg, spring_moment_Nm, pivot_friction_moment_Nm, drive_torques_Nm,
    node_displacements_m (drawn in mm) and slip_margins.  A channel of more than
    :data:`MAX_OVERLAID` lines (a drive of many spans or pulleys) is drawn as small multiples,
    one panel per line, 4 to a row, each with its own scale.  At most about 20000 points per
    line (strided).
    """
    t = np.asarray(t, dtype=float)
    names = [n for n in _SIM_CHANNELS if n in channels and channels[n] is not None]
    stride = max(1, int(np.ceil(t.size / _MAX_POINTS)))
    blocks = []  # (name, lines) per channel
    for name in names:
        _, default, _, _ = _SIM_CHANNELS[name]
        _, scale, _ = _channel_unit(name, units, default)
        blocks.append((name, [(lab, scale * y[::stride], c, ls)
                              for lab, y, c, ls in _channel_lines(name, channels[name], columns)]))
    rows = [1 if len(lines) <= MAX_OVERLAID else -(-len(lines) // _SMALL_PER_ROW) for _, lines in blocks]
    n = max(sum(rows), 1)
    fig = Figure(figsize=(11, 1.2 + 2.2 * n))
    grid = fig.add_gridspec(n, _SMALL_PER_ROW)
    first = None
    if not names:
        ax = fig.add_subplot(grid[0, :])
        ax.text(0.5, 0.5, "no channels to plot", ha="center", va="center", transform=ax.transAxes,
                fontsize=12, color="crimson")
    row, bottom = 0, []
    for (name, lines), k in zip(blocks, rows):
        label, default, _, _ = _SIM_CHANNELS[name]
        _, _, shown = _channel_unit(name, units, default)
        if len(lines) <= MAX_OVERLAID:
            panels = [(fig.add_subplot(grid[row, :], sharex=first), lines)]
        else:
            panels = [(fig.add_subplot(grid[row + j // _SMALL_PER_ROW, j % _SMALL_PER_ROW], sharex=first), [line])
                      for j, line in enumerate(lines)]
        for j, (ax, group) in enumerate(panels):
            first = first or ax
            _draw(ax, t[::stride], group, 1.0)
            ax.tick_params(labelsize=8)
            ax.grid(alpha=0.3)
            if len(panels) == 1:
                ax.set_ylabel(f"{label} ({shown})", fontsize=9)
                _legend(ax, len(group))
            else:
                ax.set_title(literal(group[0][0], 40), fontsize=8)
                if j % _SMALL_PER_ROW == 0:
                    ax.set_ylabel(f"{label} ({shown})", fontsize=8)
        row += k
        last_row = (len(panels) - 1) // _SMALL_PER_ROW
        bottom = [ax for j, (ax, _) in enumerate(panels) if j // _SMALL_PER_ROW == last_row]
    for ax in fig.axes:
        if ax not in bottom and names:
            ax.tick_params(labelbottom=False)
    for ax in bottom:
        ax.set_xlabel("time (s)")
    if t.size and first is not None and t[-1] > t[0]:  # (a run that failed at its start has one sample)
        first.set_xlim(float(t[0]), float(t[-1]))
    head = literal_wrapped(title, 110)
    note = f" (every {stride}th sample drawn)" if stride > 1 else ""
    fig.suptitle((head + "\n" if head else "") + f"time histories, {t.size} samples{note}", fontsize=10)
    plotting.save(fig, path, dpi=120, top_in=0.55 if any(k > 1 or len(b[1]) > MAX_OVERLAID for k, b in zip(rows, blocks)) else None)


def _envelope(f, a, max_points=_MAX_POINTS):
    """(f, a) reduced to at most ~max_points by the maximum over blocks (keeps the peaks)."""
    if f.size <= max_points:
        return f, a
    b = int(np.ceil(f.size / max_points))
    m = f.size // b * b
    fb, ab = f[:m].reshape(-1, b), a[:m].reshape(-1, b)
    k = np.argmax(ab, axis=1)
    rows = np.arange(fb.shape[0])
    return fb[rows, k], ab[rows, k]


def plot_spectra(t, channels, columns, units, path, *, title="", fmax=None, settle_fraction=0.0):
    """Save amplitude spectra (log scale) of a transient simulation's forces and displacements (PNG).

    Spectra (signals.spectrum: Hann window, trend and mean removed) of the part of the
    record after settle_fraction of its duration, for the channels present among
    hub_forces_N (nt, nb, 2) (one panel for the x and one for the y components, columns =
    body names), span_tensions_N and node_displacements_m (in mm; x and y panels when 3-D).
    The largest peaks of each panel (above 2 / duration) are marked with their frequency.
    t: uniform sample times (s); units: name -> unit string; fmax (Hz): upper limit of the
    plot, default min(Nyquist, 500 Hz).
    """
    from beltjax import signals

    t = np.asarray(t, dtype=float)
    keep = signals.settled(t, settle_fraction)
    tk = t[keep]
    panels = []  # (title, y label, [(label, series, colour, style)])
    for name in _SPECTRUM_CHANNELS:
        if name not in channels or channels[name] is None:
            continue
        default = {"hub_forces_N": "N", "span_tensions_N": "N", "node_displacements_m": "m"}[name]
        _, scale, shown = _channel_unit(name, units, default)
        arr = np.asarray(channels[name], dtype=float)
        lines = [(lab, scale * y[keep], c, ls) for lab, y, c, ls in _channel_lines(name, arr, columns)]
        what = {"hub_forces_N": "hub force", "span_tensions_N": "span tension",
                "node_displacements_m": "node displacement"}[name]
        if arr.ndim == 3:
            for comp, style in (("x", "-"), ("y", "--")):
                sel = [(lab, y, c, "-") for lab, y, c, ls in lines if ls == style]
                panels.append((f"{what}, {comp} component", f"amplitude ({shown})", sel))
        else:
            panels.append((what, f"amplitude ({shown})", lines))
    n = max(len(panels), 1)
    fig, axes = subplots(n, 1, figsize=(11, 1.2 + 2.5 * n), sharex=True, squeeze=False)
    axes = axes[:, 0]
    enough = tk.size >= signals.MIN_SAMPLES
    nyquist = 0.5 / float(np.mean(np.diff(tk))) if tk.size > 1 else 1.0
    top = min(nyquist, 500.0) if fmax is None else float(fmax)
    duration = float(tk[-1] - tk[0]) if tk.size > 1 else 0.0
    if not panels or not enough:
        msg = "no channels to plot" if not panels else f"only {tk.size} samples after settling: no spectrum"
        axes[0].text(0.5, 0.5, msg, ha="center", va="center", transform=axes[0].transAxes, fontsize=12,
                     color="crimson")
    for ax, (head, ylabel, lines) in zip(axes, panels if enough else []):
        peaks, drawn, a_max, curves, fs = [], 0, 0.0, [], []
        for lab, y, c, _ in lines:
            if not np.all(np.isfinite(y)):
                continue
            f, a = signals.spectrum(tk, y)
            sel = (f > 0) & (f <= top)
            fe, ae = _envelope(f[sel], a[sel])
            curves.append((lab, np.where(ae > 0, ae, np.nan), c, "-"))
            fs.append(fe)
            drawn += 1
            a_max = max(a_max, float(np.max(a[sel], initial=0.0)))
            peaks += signals.dominant_frequencies(tk, y, count=3, fmin=2.0 / duration, fmax=top)
        if curves:
            _draw(ax, fs, curves, 0.9)
        ax.set_yscale("log")
        if a_max > 0:
            ax.set_ylim(a_max * 1e-6, a_max * 100.0)  # room above the peaks for their labels
        chosen = []
        bin_hz = 1.0 / duration
        for fr, am in sorted(peaks, key=lambda p: -p[1]):
            if am >= 0.05 * max(a_max, 1e-300) and all(abs(fr - g) > 3 * bin_hz for g, _ in chosen):
                chosen.append((fr, am))
            if len(chosen) == 3:
                break
        level, prev = 0, None
        for fr, am in sorted(chosen):
            level = (level + 1) % 3 if prev is not None and fr - prev < 0.08 * top else 0  # stagger close labels
            prev = fr
            ax.plot(fr, am, marker="v", color="k", ms=5, zorder=5)
            ax.annotate(f"{fr:.1f} Hz", (fr, am), xytext=(0, 6 + 11 * level), textcoords="offset points",
                        ha="center", fontsize=8, zorder=6,
                        bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8})
        ax.set_title(head, fontsize=9, loc="left")
        ax.set_ylabel(ylabel, fontsize=9)
        ax.tick_params(labelsize=8)
        ax.grid(alpha=0.3)
        _legend(ax, drawn)
    axes[-1].set_xlabel("frequency (Hz)")
    if top > 0:  # (no frequency axis from a single sample)
        axes[-1].set_xlim(0.0, top)
    head = literal_wrapped(title, 110)
    fig.suptitle((head + "\n" if head else "")
                 + f"amplitude spectra of the last {duration:.3g} s (Hann window, trend removed; "
                 f"resolution {1.0 / max(duration, 1e-300):.3g} Hz)", fontsize=10)
    plotting.save(fig, path, dpi=120)
