"""A sweep's figures: outputs against the grid parameters, histograms, the Campbell band."""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from beltjax import drive, drive_modal, parameters
from beltjax.scene import Scene
from beltjax.sweep.spec import Spec
from beltjax.sweep.tables import LEAD_COLUMNS, columns, pooled


def _flexible_columns(cols: Mapping[str, np.ndarray], k: int = 6) -> list[str]:
    """The first ``k`` frequency columns of flexible modes, a column equal to an earlier one in every
    case (the other mode of a repeated pair) left out."""
    names = [c for c in cols if c.startswith("f") and c.endswith("_hz")]
    flex = [c for c in names if np.any(np.isfinite(cols[c])) and np.nanmax(cols[c]) >= drive_modal.RIGID_HZ]
    out: list[str] = []
    for c in flex:
        if not any(np.allclose(cols[c], cols[d], rtol=1e-6, equal_nan=True) for d in out):
            out.append(c)
    return out[:k]

def _axis_label(path: str) -> str:
    """A parameter path with its unit, drawn literally: ``belt.EI [N m^2]``."""
    from beltjax.plotting import literal

    u = parameters.unit(path)
    return literal(path, 60) + (f" [{u}]" if u else "")

def _column_label(name: str) -> str:
    """The quantity and unit of an output column (``tension_<span>_N`` -> ``span tension [N]``)."""
    if name.startswith("tension_p2p_"):
        return "dynamic span tension, peak to peak [N]"
    if name.startswith("tension_min_"):
        return "least span tension over the cycle [N]"
    for prefix, what in (("tension_", "span tension"), ("hub_", "hub force")):
        if name.startswith(prefix) and name.endswith("_N"):
            return f"{what} [N]"
    if name.startswith("f") and name.endswith("_hz"):
        return "frequency [Hz]"
    return {"installation_tension_N": "installation tension [N]", "belt_length_m": "belt length [m]",
            "tensioner_angle_deg": "tensioner arm angle [deg]", "spring_moment_Nm": "spring moment [N m]",
            "campbell_unstable_from_rpm": "unstable from [rpm]", "arm_p2p_deg": "arm motion, peak to peak [deg]",
            "dynamic_min_slip_margin": "least slip margin over the cycle [-]",
            "min_slip_margin": "least slip margin, operating point [-]"}.get(name, name)

def plot_grid(spec: Spec, cols, path: Path, labels: list[str] | None = None) -> list[Path]:
    """Outputs against the first grid parameter (lines: the other grid axes; with random samples
    the mean over the samples and a min-max band).  Writes sweep_frequencies.png and sweep_statics.png.
    Axes carry units (the parameter's, from :func:`beltjax.parameters.unit`); lines that lie on
    each other are drawn dashed over the first with a note (:func:`beltjax.plotting.coinciding`)."""
    from beltjax.plotting import coinciding, literal, literal_wrapped, overlay_style, save, subplots

    shape = (*spec.grid_shape, spec.samples if spec.random else 1)
    x = spec.grid[0].values
    others = list(np.ndindex(*shape[1:-1])) if len(shape) > 2 else [()]
    if len(others) > 12:
        others = others[:: math.ceil(len(others) / 12)]
    written = []
    groups = [("sweep_frequencies.png", _flexible_columns(cols, 6)),
              ("sweep_statics.png", [c for c in cols if c.startswith("tension_") or c.startswith("hub_")][:6])]
    for fname, names in groups:
        if not names:
            continue
        nc = min(3, len(names))
        nr = math.ceil(len(names) / nc)
        fig, axes = subplots(nr, nc, figsize=(4.6 * nc, 3.4 * nr), squeeze=False)
        for ax, name in zip(axes.flat, names):
            Y = np.asarray(cols[name], float).reshape(shape)
            curves = []
            for o in others:
                y = Y[(slice(None), *o)]
                with warnings.catch_warnings():  # all-NaN rows (failed cases) plot as gaps
                    warnings.simplefilter("ignore", RuntimeWarning)
                    mean, lo, hi = np.nanmean(y, -1), np.nanmin(y, -1), np.nanmax(y, -1)
                lab = ", ".join(f"{literal(a.parameter, 40)} = {a.values[i]:.4g}"
                                + (f" {parameters.unit(a.parameter)}" if parameters.unit(a.parameter) else "")
                                for a, i in zip(spec.grid[1:], o)) or None
                curves.append((lab, mean, lo, hi))
            over = coinciding([c[1] for c in curves])
            for j, (lab, mean, lo, hi) in enumerate(curves):
                ls, note = overlay_style(over, [c[0] or "" for c in curves], j)
                line, = ax.plot(x, mean, marker="o" if over[j] is None else "x", ms=3, ls=ls,
                                label=lab + note if lab else None)
                if shape[-1] > 1:
                    ax.fill_between(x, lo, hi, color=line.get_color(), alpha=0.2, lw=0)
            title = literal(name, 60)
            if labels and name.startswith("f") and name[1:-3].isdigit():
                m = int(name[1:-3]) - 1
                if m < len(labels):
                    title = f"{literal(name, 60)}: {literal(labels[m], 60)}"
            ax.set_title(title, fontsize=8)
            ax.set_xlabel(_axis_label(spec.grid[0].parameter), fontsize=8)
            ax.set_ylabel(_column_label(name), fontsize=8)
            ax.grid(alpha=0.3)
            ax.tick_params(labelsize=7)
            if curves[0][0] and name == names[0]:
                ax.legend(fontsize=6)
        for ax in list(axes.flat)[len(names):]:
            ax.set_visible(False)
        note = " (mean over the random samples; band: min-max)" if shape[-1] > 1 else ""
        if fname == "sweep_frequencies.png":
            note += ("\nf_k: the nominal scene's k-th mode, followed into every case by its shape (a column equal to "
                     "an earlier one in every case, a repeated pair's, is drawn once)" if labels else
                     "\nf_k: the k-th frequency of each case, sorted (a mode may change rank across cases)")
        fig.suptitle(literal_wrapped(spec.description or "parametric sweep", 120) + note, fontsize=9)
        save(fig, path / fname, dpi=100)
        written.append(path / fname)
    return written

#: most panels of sweep_histograms.png
MAX_HISTOGRAMS = 15


def _histogram_columns(cols) -> list[str]:
    """What a tolerance study is read for, first: the steady response's arm motion and least slip
    margin (``response``), the least static slip margin, the dynamic tensions of the four spans
    that swing most, the static span tensions, the lowest flexible frequencies, belt length and
    arm angle; a span tension equal to an earlier one in every case (the spans on either side of
    an idler) is left out; at most MAX_HISTOGRAMS."""
    spans = [c for c in cols if c.startswith("tension_") and not c.startswith(("tension_p2p_", "tension_min_"))]
    p2p = sorted((c for c in cols if c.startswith("tension_p2p_")), key=lambda c: -np.nanmean(np.asarray(cols[c], float))
                 if np.any(np.isfinite(np.asarray(cols[c], float))) else 0.0)[:4]  # the spans that swing most
    names = [*LEAD_COLUMNS, *p2p, *spans, *_flexible_columns(cols, 4), "belt_length_m", "tensioner_angle_deg"]
    out: list[str] = []
    for c in names:
        if c not in cols or c in out:
            continue
        y = np.asarray(cols[c], float)
        twin = c.startswith("tension_") and any(o.startswith("tension_") and np.allclose(
            y, np.asarray(cols[o], float), rtol=1e-9, atol=0.0, equal_nan=True) for o in out)
        if np.any(np.isfinite(y)) and not twin:
            out.append(c)
    return out[:MAX_HISTOGRAMS]


def plot_histograms(spec: Spec, cols, path: Path, labels: list[str] | None = None) -> Path | None:
    """Histograms of what a tolerance study is read for (:func:`_histogram_columns`:
    sweep_histograms.png); x axes: the quantity and its unit, y axes: the number of cases."""
    from beltjax.plotting import literal, literal_wrapped, save, subplots

    names = _histogram_columns(cols)
    if not names:
        return None
    nc = min(3, len(names))
    nr = math.ceil(len(names) / nc)
    fig, axes = subplots(nr, nc, figsize=(4.4 * nc, 3.4 * nr), squeeze=False)
    for ax, name in zip(axes.flat, names):
        y = np.asarray(cols[name], float)
        y = y[np.isfinite(y)]
        ax.hist(y, bins=min(40, max(5, int(np.sqrt(y.size)))), color="tab:blue", alpha=0.8)
        title = literal(name, 60)
        if labels and name.startswith("f") and name[1:-3].isdigit() and int(name[1:-3]) - 1 < len(labels):
            title = f"{title}: {literal(labels[int(name[1:-3]) - 1], 60)}"
        ax.set_title(f"{title}\nmean {y.mean():.5g}, std {y.std():.3g}", fontsize=8)
        ax.set_xlabel(_column_label(name), fontsize=8)
        ax.set_ylabel("cases", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(names):]:
        ax.set_visible(False)
    fig.suptitle(literal_wrapped(spec.description or "random sweep", 120), fontsize=9)
    save(fig, path / "sweep_histograms.png", dpi=100, top_in=0.45)
    return path / "sweep_histograms.png"

def plot_campbell_band(result, path: Path, drive_name: str, orders=(1.0, 2.0, 3.0)) -> Path:
    """Campbell curves of every case (thin lines) with order lines (sweep_campbell.png): one colour
    per mode (the nominal's, followed by its shape), its label in the legend.  A mode whose
    curves lie on an earlier mode's in every case is drawn dashed over it, with a note."""
    from beltjax.plotting import coinciding, colormap, literal, overlay_style, save, subplots

    rpm, F = result["campbell_rpm"], result["campbell_hz"]
    fig, ax = subplots(figsize=(10, 6))
    flex = [m for m in range(F.shape[2]) if np.any(np.isfinite(F[:, :, m])) and np.nanmax(F[:, :, m]) >= drive_modal.RIGID_HZ]
    colour = colormap(10)
    alpha = max(0.05, min(0.8, 8.0 / max(F.shape[0], 1)))
    over = coinciding([F[:, :, m] for m in flex])
    labels = result.get("campbell_mode_labels") or []
    names = [f"mode {m + 1}" + (f": {literal(labels[m], 60)}" if m < len(labels) else "") for m in flex]
    for j, m in enumerate(flex):
        ls, note = overlay_style(over, names, j)
        for i in range(F.shape[0]):
            ax.plot(rpm, F[i, :, m], color=colour(j), lw=0.8 if over[j] is None else 1.2, ls=ls, alpha=alpha,
                    label=names[j] + note if i == 0 else None)
    top = 1.2 * np.nanmax(F[:, 0, flex]) if flex and np.any(np.isfinite(F[:, 0, flex])) else 100.0
    ax.set_ylim(0, top)
    for k in orders:
        ax.plot(rpm, k * rpm / 60.0, ls="--", color="0.35", lw=1.0)
    ax.set_xlabel(f"{literal(drive_name, 60)} speed [rpm]")
    ax.set_ylabel("natural frequency [Hz]")
    ax.set_title(f"Campbell diagrams of {F.shape[0]} cases (order lines {', '.join(f'{k:g}x' for k in orders)})",
                 fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    save(fig, path / "sweep_campbell.png", dpi=100)
    return path / "sweep_campbell.png"

def plots(scene: Scene, spec: Spec, result: Mapping[str, np.ndarray], out: Path,
          labels: list[str] | None = None) -> list[Path]:
    """The sweep's figures in ``out``: outputs against the grid parameters, histograms of a
    random study, Campbell curves of every case (PNG paths written)."""
    cols = pooled(columns(scene, result), result)  # the flagged cases' numbers are in sweep.csv, not pooled
    files: list[Path] = []
    if spec.grid:
        files += plot_grid(spec, cols, out, labels)
    if spec.random:
        h = plot_histograms(spec, cols, out, labels)
        if h is not None:
            files.append(h)
    if "campbell_hz" in result:
        files.append(plot_campbell_band(result, out, scene.route.order[drive.drive_pulley(scene)]))
    return files
