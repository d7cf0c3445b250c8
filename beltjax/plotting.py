"""Figures (matplotlib, Agg, written to files, no screen needed): span mode shapes, a drive's
static layout, its mode shapes, and Campbell diagrams."""

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


# --------------------------------------------------------------------------- drives


def _hermite(n_per_element: int = 8, L: float = 1.0):
    """Cubic Hermite shape functions at n_per_element points of [0, 1) plus the end, shape (p, 4)."""
    xi = np.concatenate([np.arange(n_per_element) / n_per_element, [1.0]])
    return np.stack([1 - 3 * xi**2 + 2 * xi**3, L * (xi - 2 * xi**2 + xi**3), 3 * xi**2 - 2 * xi**3,
                     L * (xi**3 - xi**2)], axis=1)


def span_curve(coords, n_elements: int, Le: float, per_element: int = 8):
    """Centre line of a span (m), shape (N*per_element + 1, 2), from its nodal coordinates.

    coords: (4 (N+1),) span coordinates (x, y, x', y' per node); Le: unstretched
    element length (m).  Same cubic interpolation as the elements (vectorised numpy).
    """
    nodes = np.asarray(coords, dtype=float).reshape(n_elements + 1, 2, 2)  # node, (pos, slope), (x, y)
    S = _hermite(per_element, Le)  # (p+1, 4)
    elem = np.concatenate([nodes[:-1], nodes[1:]], axis=1)  # (N, 4, 2)
    r = np.einsum("pk,ekd->epd", S[:-1], elem).reshape(-1, 2)
    return np.vstack([r, S[-1] @ elem[-1]])


def _drive_extent(centers, radii):
    c, r = np.asarray(centers), np.asarray(radii)
    lo = np.min(c - r[:, None], axis=0)
    hi = np.max(c + r[:, None], axis=0)
    return lo, hi


def _draw_pulleys(ax, scene, centers, radii, angles=None, color="0.25", lw=1.5, ls="-", names=True,
                  fill=True):
    """Pulleys as circles (filled lightly), optional spoke showing a rotation angle (rad), names."""
    order = scene.route.order
    for i, name in enumerate(order):
        c, r = np.asarray(centers[i]), float(radii[i])
        if fill:
            ax.add_patch(plt.Circle(c, r, facecolor="0.93", edgecolor="none", zorder=1))
        ax.add_patch(plt.Circle(c, r, fill=False, edgecolor=color, lw=lw, ls=ls, zorder=2))
        ax.plot(*c, marker="+", color=color, ms=6, zorder=3)
        if angles is not None:
            a = float(angles[i])
            ax.plot([c[0], c[0] + r * np.cos(a)], [c[1], c[1] + r * np.sin(a)], color=color, lw=lw, zorder=3)
        if names:
            ax.annotate(name, c, xytext=(0, -10), textcoords="offset points", ha="center", va="top", fontsize=8,
                        color="0.15", zorder=6)


def _draw_arm(ax, scene, idler_center, color="tab:brown", label=None, lw=3.0, ls="-"):
    t = scene.tensioner
    p = np.asarray(t.pivot)
    ax.plot([p[0], idler_center[0]], [p[1], idler_center[1]], color=color, lw=lw, ls=ls, solid_capstyle="round",
            label=label, zorder=4)
    ax.plot(*p, marker="o", color=color, ms=6, mfc="white", mew=2, zorder=5)


def _span_curves(scene, q, inst):
    from beltjax import drive

    E, _ = drive.split_full(np.asarray(q), scene)
    N = drive.span_elements(scene)
    Le = np.asarray(drive.element_length(scene, inst))
    return [span_curve(E[s], N, float(Le[s])) for s in range(E.shape[0])]


def _wrapped(text: str, width: int = 80) -> str:
    import textwrap

    return "\n".join(textwrap.wrap(text, width)) if text else ""


def plot_layout(scene, result, path):
    """Save the drive drawn to scale at its static state (PNG).

    Pulleys (names), tensioner pivot and arm, the spans from the static nodal
    coordinates with their tensions at mid-span, and the belt's force on each
    hub as an arrow (scaled; value in N).  result: a StaticResult.
    """
    inst = result.inst
    centers, radii = np.asarray(inst.centers), np.asarray(inst.radii)
    order = scene.route.order
    lo, hi = _drive_extent(centers, radii)
    size = float(np.max(hi - lo))
    mid = 0.5 * (lo + hi)
    pad = 0.12 * size
    span_xy = (hi - lo) + 2 * pad
    width = 10.0
    height = float(np.clip(width * span_xy[1] / span_xy[0], 3.0, 10.0)) + 1.3  # room for the title and labels
    fig, ax = plt.subplots(figsize=(width, height))
    _draw_pulleys(ax, scene, centers, radii)
    if scene.tensioner is not None:
        _draw_arm(ax, scene, centers[order.index("tensioner")], label="tensioner arm (pivot o)")
    curves = _span_curves(scene, result.q, inst)
    for s, (name, curve, T) in enumerate(zip(result.span_names, curves, result.span_tensions_N)):
        ax.plot(curve[:, 0], curve[:, 1], color="tab:blue", lw=2.2, label="belt span" if s == 0 else None, zorder=3)
        m = curve[len(curve) // 2]
        tan = curve[-1] - curve[0]
        d = np.array([-tan[1], tan[0]]) / max(np.linalg.norm(tan), 1e-12)  # normal to the span
        if np.dot(d, m - mid) < 0:  # label on the side away from the drive's centre
            d = -d
        ha = "center" if abs(d[0]) < 0.4 else ("left" if d[0] > 0 else "right")
        va = "center" if abs(d[1]) < 0.4 else ("bottom" if d[1] > 0 else "top")
        ax.annotate(f"{name}\nT = {float(T):.1f} N", m, xytext=(26 * d[0], 26 * d[1]), textcoords="offset points",
                    ha=ha, va=va, fontsize=8, color="tab:blue", zorder=8,
                    arrowprops=dict(arrowstyle="-", color="tab:blue", lw=0.6, shrinkA=0, shrinkB=0),
                    bbox=dict(boxstyle="round,pad=0.2", fc="white", ec="tab:blue", alpha=0.85))
    F = {k: np.asarray(v, float) for k, v in result.hub_forces_N.items()}
    fmax = max([np.hypot(*v) for v in F.values()] + [1e-12])
    scale = 0.25 * size / fmax  # m per N
    for i, name in enumerate(order):
        f = F[name]
        c = centers[i]
        ax.annotate("", xy=c + scale * f, xytext=c, zorder=7,
                    arrowprops=dict(arrowstyle="-|>", color="tab:red", lw=2, mutation_scale=15))
        ax.annotate(f"{np.hypot(*f):.0f} N", c + scale * f, xytext=(4, 4), textcoords="offset points",
                    fontsize=8, color="tab:red", zorder=7)
    ax.plot([], [], color="tab:red", lw=2, label=f"belt force on hub (1 m = {1 / scale:.0f} N)")
    ax.set_aspect("equal")
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(alpha=0.3)
    sub = f"static state at belt speed {result.speed_m_s:g} m/s"
    if result.tensioner_angle_deg is not None:
        sub += f", tensioner arm angle {result.tensioner_angle_deg:.2f} deg"
    title = _wrapped(scene.description or scene.source or "belt drive", 100)
    ax.set_title((title + "\n" if title else "") + sub, fontsize=10)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _mode_displacement(scene, modal_result, m, size, fraction: float = 0.08):
    """Static full coordinates and the displacement of mode m (J v, by the kinematic map's
    Jacobian), scaled so that the largest node or pulley-centre displacement is fraction*size."""
    import jax
    import jax.numpy as jnp

    from beltjax import drive

    st = modal_result.statics
    inst = st.inst
    qi0 = jnp.asarray(st.qi)
    v = jnp.asarray(modal_result.mode_shapes[:, m])
    phi = lambda x: drive.full_coordinates(x, scene, inst)  # noqa: E731
    q0, dq = jax.jvp(phi, (qi0,), (v,))
    E, B = drive.split_full(np.asarray(dq), scene)
    pos = np.concatenate([E.reshape(E.shape[0], -1, 4)[:, :, :2].reshape(-1, 2), B[:, :2]])
    biggest = float(np.max(np.hypot(pos[:, 0], pos[:, 1])))
    if not np.isfinite(biggest) or biggest <= 0:
        return np.asarray(q0), np.zeros_like(np.asarray(q0))
    # the linearised map (J v): with an exaggerated amplitude the exact map would bend the
    # tensioner arm's arc while the span nodes move along straight lines
    return np.asarray(q0), fraction * size / biggest * np.asarray(dq)


def flexible_modes(modal_result, n: int = 6, pool: int | None = None):
    """Indices of the first n modes above the rigid-body threshold (among the first ``pool``)."""
    from beltjax.drive_modal import RIGID_HZ

    f = np.asarray(modal_result.frequencies_hz)
    k = len(f) if pool is None else min(pool, len(f))
    return [i for i in range(k) if np.isfinite(f[i]) and f[i] >= RIGID_HZ][:n]


def plot_drive_modes(scene, modal_result, path, n_modes: int = 6, pool: int | None = None):
    """Save the first flexible mode shapes of a drive drawn on its layout (PNG).

    The static drive in grey, the displaced spans and pulleys in colour
    (displacements scaled to about 8 % of the drive's size; a spoke shows a
    pulley's rotation).  modal_result: a ModalResult; pool: choose among its
    first ``pool`` modes only.
    """
    from beltjax import drive

    picks = flexible_modes(modal_result, n_modes, pool) if modal_result.stable else []
    st = modal_result.statics
    inst = st.inst
    centers, radii = np.asarray(inst.centers), np.asarray(inst.radii)
    lo, hi = _drive_extent(centers, radii)
    size = float(np.max(hi - lo))
    pad = 0.15 * size
    n = max(len(picks), 1)
    ncol = min(3, n)
    nrow = int(np.ceil(n / ncol))
    aspect = float(np.clip((hi - lo + 2 * pad)[1] / (hi - lo + 2 * pad)[0], 0.25, 1.5))
    panel = 4.6
    width = max(panel * ncol + 0.4, 9.5)  # room for the title with one panel
    fig, axes = plt.subplots(nrow, ncol, figsize=(width, (panel * aspect + 1.1) * nrow + 0.7), squeeze=False)
    axes = axes.ravel()
    static_curves = _span_curves(scene, st.q, inst)
    order = scene.route.order
    n_route = len(order)

    def base(ax):
        _draw_pulleys(ax, scene, centers, radii, angles=np.zeros(n_route), color="0.6", lw=1.0, names=False)
        for s, c in enumerate(static_curves):
            ax.plot(c[:, 0], c[:, 1], color="0.6", lw=1.2, label="static drive" if s == 0 else None)
        if scene.tensioner is not None:
            _draw_arm(ax, scene, centers[order.index("tensioner")], color="0.6", lw=2.0)
        ax.set_aspect("equal")
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
        ax.set_xlabel("x [m]", fontsize=8)
        ax.set_ylabel("y [m]", fontsize=8)
        ax.tick_params(labelsize=7)

    if not picks:
        ax = axes[0]
        base(ax)
        msg = ("unstable: past the critical speed\nno natural frequencies" if not modal_result.stable
               else "no flexible modes to show")
        ax.text(0.5, 0.5, msg, ha="center", va="center", transform=ax.transAxes, fontsize=12, color="crimson")
    for ax, m in zip(axes, picks):
        base(ax)
        q0, dq = _mode_displacement(scene, modal_result, m, size)
        q1 = q0 + dq
        for s, c in enumerate(_span_curves(scene, q1, inst)):
            ax.plot(c[:, 0], c[:, 1], color="tab:blue", lw=1.8, label="mode shape (scaled)" if s == 0 else None)
        _, B = drive.split_full(q1, scene)
        _draw_pulleys(ax, scene, B[:n_route, :2], radii, angles=B[:n_route, 2], color="tab:red", lw=1.2,
                      names=False, fill=False)
        if scene.tensioner is not None:
            _draw_arm(ax, scene, B[order.index("tensioner"), :2], color="tab:red", lw=2.0)
        ax.set_title(f"mode {m + 1}: {modal_result.frequencies_hz[m]:.2f} Hz\n{modal_result.labels[m]}", fontsize=9)
    for ax in axes[len(picks) if picks else 1:]:
        ax.set_visible(False)
    axes[0].legend(fontsize=7, loc="upper right")
    title = _wrapped(scene.description or scene.source or "belt drive", int(11 * width))
    fig.suptitle((title + "\n" if title else "")
                 + _wrapped(f"mode shapes at belt speed {modal_result.speed_m_s:g} m/s (displacements exaggerated; "
                            "spokes show pulley rotation)", int(11 * width)), fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_campbell(result, path, title: str = "", bands=()):
    """Save a Campbell diagram (PNG): mode frequencies against drive-pulley speed, order lines, crossings.

    result: a CampbellResult.  One colour and one legend entry per column (a tracked mode: its
    label, and where it changes along the curve, the new label and the speed); crossings are
    dots in their mode's colour.  Rigid-body (0 Hz) modes are not drawn; speeds
    without frequencies (``stable`` false: unstable, or no equilibrium) are shaded.
    bands: speed bands to highlight, each ``(rpm_low, rpm_high, orders, note)``: the band is
    shaded and its order lines [k x rpm/60 Hz] drawn bold inside it, with the note as a label.
    """
    from beltjax.drive_modal import RIGID_HZ

    rpm = np.asarray(result.rpm, float)
    F = np.asarray(result.frequencies_hz, float)
    finite_max = np.array([np.nanmax(F[:, m]) if np.any(np.isfinite(F[:, m])) else np.nan for m in range(F.shape[1])])
    modes = [m for m in range(F.shape[1]) if np.isfinite(finite_max[m]) and finite_max[m] >= RIGID_HZ]
    fig, ax = plt.subplots(figsize=(12, 7))
    cmap = plt.get_cmap("tab20" if len(modes) > 10 else "tab10")
    colors = {m: cmap(j % cmap.N) for j, m in enumerate(modes)}
    changes = {}
    for c in getattr(result, "label_changes", None) or []:
        changes.setdefault(c["mode"] - 1, []).append(c)
    drawn = []
    for m in modes:
        lab = result.labels[m] if m < len(result.labels) else f"mode {m + 1}"
        lab += "".join(f" -> {c['to']} ({c['rpm']:g} rpm)" for c in changes.get(m, []))
        # a curve on top of one already drawn (a repeated pair): dashed, so both show
        same = next((d for d in drawn if np.array_equal(np.isfinite(F[:, d]), np.isfinite(F[:, m]))
                     and np.allclose(F[:, d], F[:, m], rtol=1e-6, atol=1e-9, equal_nan=True)), None)
        if same is not None:
            lab += f" (same as {same + 1})"
        drawn.append(m)
        ax.plot(rpm, F[:, m], color=colors[m], lw=1.6, marker="." if len(rpm) <= 12 else None,
                ls=(0, (4, 4)) if same is not None else "-", label=_wrapped(f"{m + 1}: {lab}", 60))
    # y-limit: 1.2 x the highest plotted frequency at the lowest speed with finite values
    first = next((i for i in range(len(rpm)) if np.any(np.isfinite(F[i, modes]))), None) if modes else None
    top = 1.2 * float(np.nanmax(F[first, modes])) if first is not None else 100.0
    if not np.isfinite(top) or top <= 0:
        top = 100.0
    ax.set_ylim(0, top)
    x0, x1 = float(rpm[0]), float(rpm[-1])
    if x1 == x0:
        x1 = x0 + 1.0
    ax.set_xlim(x0, x1)
    for k in result.orders:
        xs = np.array([x0, x1])
        ax.plot(xs, k * xs / 60.0, ls="--", color="0.35", lw=1.0)
        x_end = min(x1, top * 60.0 / k) if k > 0 else x1
        ax.annotate(f"{k:g}x", (x_end, k * x_end / 60.0), xytext=(-4, -10 if x_end < x1 else 3),
                    textcoords="offset points", ha="right", fontsize=9, color="0.2")
    ax.plot([], [], ls="--", color="0.35", lw=1.0, label="order lines (k x rpm/60)")
    unstable = ~(np.asarray(result.stable, bool) & np.asarray(result.converged, bool))
    if np.any(unstable):
        step = (rpm[1] - rpm[0]) / 2 if len(rpm) > 1 else 0.5
        for i in np.flatnonzero(unstable):
            ax.axvspan(rpm[i] - step, rpm[i] + step, color="crimson", alpha=0.12, lw=0)
        ax.plot([], [], color="crimson", alpha=0.3, lw=8, label="no frequencies (unstable or no equilibrium)")
    for lo, hi, band_orders, note in bands:
        ax.axvspan(lo, hi, color="gold", alpha=0.18, lw=0, zorder=0)
        for k in band_orders:
            xs = np.array([lo, hi], float)
            ax.plot(xs, k * xs / 60.0, color="darkorange", lw=3.0, alpha=0.8, zorder=4)
        if note:
            ax.text(0.5 * (lo + hi), 0.98 * top, note, ha="center", va="top", fontsize=8, color="0.2",
                    bbox=dict(boxstyle="round,pad=0.2", fc="white", ec="darkorange", alpha=0.85))
    cx = [c for c in result.crossings if c["mode"] - 1 in colors]
    if cx:
        ax.scatter([c["rpm"] for c in cx], [c["frequency_hz"] for c in cx], s=36, zorder=5,
                   c=[colors[c["mode"] - 1] for c in cx], edgecolors="k", linewidths=0.8, label="crossing")
    ax.set_xlabel(f"{result.drive_pulley} speed [rpm]")
    ax.set_ylabel("natural frequency [Hz]")
    ax.grid(alpha=0.3)
    head = _wrapped(title, 100)
    note = "" if result.transport else " (no 'transport' effect: frequencies independent of speed)"
    ax.set_title((head + "\n" if head else "") + f"Campbell diagram{note}", fontsize=10)
    n_entries = len(modes) + 2
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0,
              ncol=1 if n_entries <= 28 else 2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# --------------------------------------------------------------------------- transient simulations

# channel -> (panel label, default unit, factor to the plotted unit, plotted unit), in the preferred order
_SIM_CHANNELS = {
    "span_tensions_N": ("span tension", "N", 1.0, None),
    "span_forces_N": ("span force", "N", 1.0, None),
    "hub_force_magnitudes_N": ("hub force magnitude", "N", 1.0, None),
    "pulley_speeds_rpm": ("pulley speed", "rpm", 1.0, None),
    "arm_angle_deg": ("tensioner arm angle", "deg", 1.0, None),
    "spring_moment_Nm": ("tensioner spring moment", "N m", 1.0, None),
    "drive_torques_Nm": ("drive torque", "N m", 1.0, None),
    "node_displacements_m": ("node displacement", "m", 1e3, "mm"),
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


def _colour(n_lines):
    cmap = plt.get_cmap("tab20" if n_lines > 10 else "tab10")
    return lambda j: cmap(j % cmap.N)


def _legend(ax, n):
    if n > 1:
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0,
                  ncol=1 + (n - 1) // 16, handlelength=1.8)


def plot_simulation(t, channels, columns, units, path, *, title=""):
    """Save stacked time histories of a transient simulation (PNG), one panel per channel.

    t: sample times (s), shape (nt,); channels: name -> array (nt,), (nt, k) or (nt, k, 2)
    (x solid, y dashed); columns: name -> column labels (span, pulley or node names);
    units: name -> unit string (defaults from the channel name).  Panels, in this order,
    for the channels present: span_tensions_N, span_forces_N, hub_force_magnitudes_N,
    pulley_speeds_rpm, arm_angle_deg, spring_moment_Nm, drive_torques_Nm and
    node_displacements_m (drawn in mm).  At most about 20000 points per line (strided).
    """
    t = np.asarray(t, dtype=float)
    names = [n for n in _SIM_CHANNELS if n in channels and channels[n] is not None]
    stride = max(1, int(np.ceil(t.size / _MAX_POINTS)))
    n = max(len(names), 1)
    fig, axes = plt.subplots(n, 1, figsize=(11, 1.2 + 2.2 * n), sharex=True, squeeze=False)
    axes = axes[:, 0]
    if not names:
        axes[0].text(0.5, 0.5, "no channels to plot", ha="center", va="center", transform=axes[0].transAxes,
                     fontsize=12, color="crimson")
    for ax, name in zip(axes, names):
        label, default, _, _ = _SIM_CHANNELS[name]
        _, scale, shown = _channel_unit(name, units, default)
        lines = _channel_lines(name, channels[name], columns)
        colour = _colour(max(c for _, _, c, _ in lines) + 1)
        for lab, y, c, ls in lines:
            ax.plot(t[::stride], scale * y[::stride], lw=1.0, ls=ls, color=colour(c), label=lab)
        ax.set_ylabel(f"{label} ({shown})", fontsize=9)
        ax.tick_params(labelsize=8)
        ax.grid(alpha=0.3)
        _legend(ax, len(lines))
    axes[-1].set_xlabel("time (s)")
    if t.size:
        axes[-1].set_xlim(float(t[0]), float(t[-1]))
    head = _wrapped(title, 110)
    note = f" (every {stride}th sample drawn)" if stride > 1 else ""
    fig.suptitle((head + "\n" if head else "") + f"time histories, {t.size} samples{note}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


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
    fig, axes = plt.subplots(n, 1, figsize=(11, 1.2 + 2.5 * n), sharex=True, squeeze=False)
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
        colour = _colour(max([c for _, _, c, _ in lines] + [0]) + 1)
        peaks, drawn, a_max = [], 0, 0.0
        for lab, y, c, _ in lines:
            if not np.all(np.isfinite(y)):
                continue
            f, a = signals.spectrum(tk, y)
            sel = (f > 0) & (f <= top)
            fe, ae = _envelope(f[sel], a[sel])
            ax.plot(fe, np.where(ae > 0, ae, np.nan), lw=0.9, color=colour(c), label=lab)
            drawn += 1
            a_max = max(a_max, float(np.max(a[sel], initial=0.0)))
            peaks += signals.dominant_frequencies(tk, y, count=3, fmin=2.0 / duration, fmax=top)
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
    axes[-1].set_xlim(0.0, top)
    head = _wrapped(title, 110)
    fig.suptitle((head + "\n" if head else "")
                 + f"amplitude spectra of the last {duration:.3g} s (Hann window, trend removed; "
                 f"resolution {1.0 / max(duration, 1e-300):.3g} Hz)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
