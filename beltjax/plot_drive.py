"""A drive's figures: its static layout (pulleys, spans, the tensioner arm), its mode shapes and its
Campbell diagram (m, Hz, rpm; user text drawn literally through :func:`beltjax.plotting.literal`)."""

from __future__ import annotations

import textwrap

import numpy as np
from matplotlib.patches import Circle

from beltjax import ancf, plotting  # plotting.save, looked up at each call (tests watch it)
from beltjax.plotting import MAX_MODE_PANELS, coinciding, colormap, literal, literal_wrapped, overlay_style, subplots


def _hermite(n_per_element: int = 8, L: float = 1.0):
    """Cubic Hermite shape functions at n_per_element points of [0, 1) plus the end, shape (p, 4)."""
    xi = np.concatenate([np.arange(n_per_element) / n_per_element, [1.0]])
    return np.asarray(ancf.shape_functions(xi, L)).T  # the elements' own (one place: beltjax.ancf)


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
                  fill=True, fontsize=8, limit=40):
    """Pulleys as circles (filled lightly), optional spoke showing a rotation angle (rad), names
    (drawn literally, below the centre)."""
    order = scene.route.order
    for i, name in enumerate(order):
        c, r = np.asarray(centers[i]), float(radii[i])
        if fill:
            ax.add_patch(Circle(c, r, facecolor="0.93", edgecolor="none", zorder=1))
        ax.add_patch(Circle(c, r, fill=False, edgecolor=color, lw=lw, ls=ls, zorder=2))
        ax.plot(*c, marker="+", color=color, ms=6, zorder=3)
        if angles is not None:
            a = float(angles[i])
            ax.plot([c[0], c[0] + r * np.cos(a)], [c[1], c[1] + r * np.sin(a)], color=color, lw=lw, zorder=3)
        if names:
            ax.annotate(literal(name, limit), c, xytext=(0, -10), textcoords="offset points", ha="center", va="top",
                        fontsize=fontsize, color="0.15", zorder=6)


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
    fig, ax = subplots(figsize=(width, height))
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
        ax.annotate(f"{literal(name, 60)}\nT = {float(T):.1f} N", m, xytext=(26 * d[0], 26 * d[1]), textcoords="offset points",
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
    title = literal_wrapped(scene.description or scene.source or "belt drive", 100)
    ax.set_title((title + "\n" if title else "") + sub, fontsize=10)
    ax.legend(fontsize=8, loc="best")
    plotting.save(fig, path, dpi=120)


def _mode_displacements(scene, modal_result, modes, size, fraction: float = 0.08):
    """Static full coordinates q0 and the displacements of the given modes (J v, with J the
    kinematic map's Jacobian, computed once in one compiled call: under a second for any
    number of modes), each scaled so that its largest node or pulley-centre displacement is
    fraction*size.  Returns (q0, [dq per mode])."""
    import jax
    import jax.numpy as jnp

    from beltjax import drive

    st = modal_result.statics
    inst = st.inst
    phi = lambda x: drive.full_coordinates(x, scene, inst)  # noqa: E731
    q0, J = jax.jit(lambda x: (phi(x), jax.jacfwd(phi)(x)))(jnp.asarray(st.qi))
    q0 = np.asarray(q0)
    dQ = (np.asarray(J) @ np.asarray(modal_result.mode_shapes)[:, list(modes)]).T
    out = []
    for dq in dQ:
        E, B = drive.split_full(dq, scene)
        pos = np.concatenate([E.reshape(E.shape[0], -1, 4)[:, :, :2].reshape(-1, 2), B[:, :2]])
        biggest = float(np.max(np.hypot(pos[:, 0], pos[:, 1])))
        # the linearised map (J v): with an exaggerated amplitude the exact map would bend the
        # tensioner arm's arc while the span nodes move along straight lines
        ok = np.isfinite(biggest) and biggest > 0
        out.append(fraction * size / biggest * dq if ok else np.zeros_like(q0))
    return q0, out


def flexible_modes(modal_result, n: int = 6, pool: int | None = None):
    """Indices of the first n modes above the rigid-body threshold (among the first ``pool``)."""
    from beltjax.drive_modal import RIGID_HZ

    f = np.asarray(modal_result.frequencies_hz)
    k = len(f) if pool is None else min(pool, len(f))
    return [i for i in range(k) if np.isfinite(f[i]) and f[i] >= RIGID_HZ][:n]


def mode_panels(modal_result, n_modes: int = 6, pool: int | None = None) -> tuple[list[int], int]:
    """(modes drawn by :func:`plot_drive_modes`, flexible modes among the first ``pool``): the
    first min(n_modes, MAX_MODE_PANELS) flexible modes."""
    if not modal_result.stable:
        return [], 0
    every = flexible_modes(modal_result, len(modal_result.frequencies_hz), pool)
    return every[: min(n_modes, MAX_MODE_PANELS)], len(every)


def _grid(n: int) -> tuple[int, int]:
    """(rows, columns) of n panels: up to 3 columns for 9 panels or fewer, else 4."""
    ncol = min(n, 3 if n <= 9 else 4)
    return int(np.ceil(n / ncol)), ncol


def plot_drive_modes(scene, modal_result, path, n_modes: int = 6, pool: int | None = None):
    """Save the first flexible mode shapes of a drive drawn on its layout (PNG); returns the
    figure (one visible panel per mode drawn, see :func:`mode_panels`).

    The static drive in grey with the pulleys' names, the displaced spans and pulleys in
    colour (displacements scaled to about 8 % of the drive's size; a spoke shows a pulley's
    rotation).  modal_result: a ModalResult; n_modes: panels wanted (at most
    ``MAX_MODE_PANELS``; the title says when more flexible modes were asked for); pool:
    choose among its first ``pool`` modes only.
    """
    from beltjax import drive

    picks, available = mode_panels(modal_result, n_modes, pool)
    st = modal_result.statics
    inst = st.inst
    centers, radii = np.asarray(inst.centers), np.asarray(inst.radii)
    lo, hi = _drive_extent(centers, radii)
    size = float(np.max(hi - lo))
    pad = 0.15 * size
    n = max(len(picks), 1)
    nrow, ncol = _grid(n)
    aspect = float(np.clip((hi - lo + 2 * pad)[1] / (hi - lo + 2 * pad)[0], 0.25, 1.5))
    panel = 4.6 if ncol <= 3 else 4.2
    width = max(panel * ncol + 0.4, 9.5)  # room for the title with one panel
    fig, axes = subplots(nrow, ncol, figsize=(width, (panel * aspect + 1.1) * nrow + 0.9), squeeze=False)
    axes = axes.ravel()
    static_curves = _span_curves(scene, st.q, inst)
    order = scene.route.order
    n_route = len(order)

    def base(ax):
        _draw_pulleys(ax, scene, centers, radii, angles=np.zeros(n_route), color="0.6", lw=1.0, names=True,
                      fontsize=7, limit=30)
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
    q0, shapes = _mode_displacements(scene, modal_result, picks, size) if picks else (None, [])
    for ax, m, dq in zip(axes, picks, shapes):
        base(ax)
        q1 = q0 + dq
        for s, c in enumerate(_span_curves(scene, q1, inst)):
            ax.plot(c[:, 0], c[:, 1], color="tab:blue", lw=1.8, label="mode shape (scaled)" if s == 0 else None)
        _, B = drive.split_full(q1, scene)
        _draw_pulleys(ax, scene, B[:n_route, :2], radii, angles=B[:n_route, 2], color="tab:red", lw=1.2,
                      names=False, fill=False)
        if scene.tensioner is not None:
            _draw_arm(ax, scene, B[order.index("tensioner"), :2], color="tab:red", lw=2.0)
        label = literal_wrapped(modal_result.labels[m], 48, max_lines=2)
        ax.set_title(f"mode {m + 1}: {modal_result.frequencies_hz[m]:.2f} Hz\n{label}", fontsize=9)
    for ax in axes[len(picks) if picks else 1:]:
        ax.set_visible(False)
    axes[0].legend(fontsize=7, loc="upper right")
    chars = int(11 * width)
    title = literal_wrapped(scene.description or scene.source or "belt drive", chars)
    shown = ""
    if picks and available > len(picks):
        shown = (f"; the first {len(picks)} of {available} flexible modes asked for"
                 + (f" (at most {MAX_MODE_PANELS} panels)" if len(picks) == MAX_MODE_PANELS else ""))
    sub = (f"mode shapes at belt speed {modal_result.speed_m_s:g} m/s (displacements exaggerated; "
           f"spokes show pulley rotation){shown}")
    fig.suptitle((title + "\n" if title else "") + "\n".join(textwrap.wrap(sub, chars)), fontsize=10)
    plotting.save(fig, path, dpi=110)
    return fig


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
    fig, ax = subplots(figsize=(12, 7))
    colour = colormap(len(modes))
    colors = {m: colour(j) for j, m in enumerate(modes)}
    changes = {}
    for c in getattr(result, "label_changes", None) or []:
        changes.setdefault(c["mode"] - 1, []).append(c)
    labels = [literal(f"{m + 1}: {result.labels[m] if m < len(result.labels) else f'mode {m + 1}'}"
                      + "".join(f" -> {c['to']} ({c['rpm']:g} rpm)" for c in changes.get(m, [])), 90)
              for m in modes]
    over = coinciding([F[:, m] for m in modes])
    for j, m in enumerate(modes):
        ls, note = overlay_style(over, [f"mode {k + 1}" for k in modes], j)
        ax.plot(rpm, F[:, m], color=colors[m], lw=1.6, ls=ls, marker="." if len(rpm) <= 12 else None,
                label=labels[j] + note)
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
            ax.text(0.5 * (lo + hi), 0.98 * top, literal(note), ha="center", va="top", fontsize=8, color="0.2",
                    bbox=dict(boxstyle="round,pad=0.2", fc="white", ec="darkorange", alpha=0.85))
    cx = [c for c in result.crossings if c["mode"] - 1 in colors]
    if cx:
        ax.scatter([c["rpm"] for c in cx], [c["frequency_hz"] for c in cx], s=36, zorder=5,
                   c=[colors[c["mode"] - 1] for c in cx], edgecolors="k", linewidths=0.8, label="crossing")
    ax.set_xlabel(f"{literal(result.drive_pulley, 60)} speed [rpm]")
    ax.set_ylabel("natural frequency [Hz]")
    ax.grid(alpha=0.3)
    head = literal_wrapped(title, 100)
    note = "" if result.transport else " (no 'transport' effect: frequencies independent of speed)"
    ax.set_title((head + "\n" if head else "") + f"Campbell diagram{note}", fontsize=10)
    n_entries = len(modes) + 2
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0,
              ncol=1 if n_entries <= 28 else 2)
    plotting.save(fig, path, dpi=110)
