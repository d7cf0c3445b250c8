"""Reports on a layout: constraints, resonance bands, and the check on the scene's own mesh."""

from __future__ import annotations

import functools
import math
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from beltjax import drive, drive_modal, modal, static_state, statics
from beltjax.scene import Scene
from beltjax.optimize.goal import overlaps
from beltjax.optimize.loss import (WATCHED, _compiled, _loss_key, _measures_jit, _violations, band_need,
                                   band_weights, problem_masks, terms_from_measures)
from beltjax.optimize.problem import _UNIT_NAME, OptimizeError, Problem, _band_starts, _bands, sample_rpm
from beltjax.optimize.solver import OptimizeResult, _floats
from beltjax.drive.effects import effects_of


def constraint_report(m: dict, scene: Scene, problem: Problem) -> list[dict]:
    """Each constraint's value, worst violation (its units) and whether it holds within its
    tolerance, from :func:`measures`-like numpy values ``m``."""
    out = []
    for j, c in enumerate(problem.constraints):
        keys = ("wrap_deg", "tensions_N", "arm_deg", "gaps_m", "slip_margins")
        viol, value = _violations(c, {k: np.asarray(m[k]) for k in keys if k in m}, scene, np)
        worst = float(np.max(viol)) if np.size(viol) else 0.0
        value = [float(v) for v in value] if isinstance(value, tuple) else float(value)
        out.append(dict(constraint=j, kind=c.kind, where=c.where, lower=c.lower, upper=c.upper,
                        unit=_UNIT_NAME[c.kind], value=value, violation=worst, tolerance=c.tolerance,
                        satisfied=bool(worst <= c.tolerance)))
    return out


def _describe_constraint(c: dict) -> str:
    u = c["unit"]
    if c["kind"] == "min_wrap_deg":
        return f"wrap {c['where'] or 'every pulley'} >= {c['lower']:g} {u}"
    if c["kind"] == "no_overlap":
        return f"clearance between pulleys >= {c['lower']:g} {u}"
    if c["kind"] == "min_slip_margin":
        return f"slip margin {c['where'] or 'every arc'} >= {c['lower']:g} (operating point, capstan law)"
    what = "span tension" + (f" {c['where']}" if c["where"] else "") if c["kind"] == "static_tension" else "arm angle"
    lo = "" if c["lower"] is None else f"{c['lower']:g} <= "
    hi = "" if c["upper"] is None else f" <= {c['upper']:g}"
    return f"{lo}{what}{hi} {u}"


def _value_text(c: dict) -> str:
    v = c["value"]
    fmt = (lambda x: f"{x:.4g}") if c["kind"] != "no_overlap" else (lambda x: f"{x:.4f}")  # noqa: E731
    text = f"{fmt(v[0])}..{fmt(v[1])}" if isinstance(v, list) else fmt(v)
    return text + ("" if c["satisfied"] else f" (violated by {c['violation']:.3g})")


def resonance_report(rpm, freqs, labels, problem: Problem, masks, weights=None) -> list[dict]:
    """Per resonance objective, from a Campbell sweep (rpm (n,), freqs (n, m) Hz; NaN where
    unstable): crossings of the watched modes with the order lines inside the band, the closest
    approach (Hz) of a watched mode to an order line in the band, and the largest shift still
    needed (Hz, exact max over the band's speeds of the sweep) with the mode that needs it; the
    band is clear when that shift is within its tolerance_hz and no speed in it is unstable.

    masks: :func:`~beltjax.optimize.loss.mode_masks`; weights (n, m): the span weights of
    :func:`~beltjax.optimize.loss.measures` at each speed (a sorted mode is watched at a speed
    where its weight is 1; needed with modes = "span", None: 1); labels: the labels (m,)
    used at every speed, or a callable i -> labels (m,) at rpm[i] (each mode is named where it
    is reported).  A band with an unstable speed inside is not clear (``unstable_rpm``).
    """
    from beltjax import campbell

    rpm, freqs = np.asarray(rpm, float), np.asarray(freqs, float)
    label_at = labels if callable(labels) else (lambda i: labels)
    W_all = np.ones_like(freqs) if weights is None else np.asarray(weights, float)
    out = []
    for j, o in enumerate(_bands(problem)):
        idx = np.flatnonzero((rpm >= o.rpm[0] - 1e-9) & (rpm <= o.rpm[1] + 1e-9))
        F, r = freqs[idx], rpm[idx]
        W = np.where(np.isfinite(F), band_weights(dict(span_weights=W_all), problem, masks, j, idx, np), 0.0)
        sel = W >= WATCHED  # (K, m): watched there
        modes = [int(k) for k in np.flatnonzero(np.any(sel, axis=0))]
        cx = []
        for c in campbell.crossings(r, F, o.orders):
            i = min(int(np.searchsorted(r, c["rpm"])), r.size - 1)
            i = i - 1 if i > 0 and c["rpm"] - r[i - 1] < r[i] - c["rpm"] else i  # the nearer sampled speed
            if sel[i, c["mode"] - 1]:
                cx.append(dict(c, label=label_at(idx[i])[c["mode"] - 1]))
        g = F[None] - np.asarray(o.orders)[:, None, None] * r[None, :, None] / 60.0  # (o, K, m)
        dist = np.where(sel[None] & np.isfinite(g), np.abs(g), np.inf)
        a = np.unravel_index(np.argmin(dist), dist.shape)
        need = band_need(np.nan_to_num(F, nan=0.0), r, np.asarray(o.orders), o.margin_hz, soft=False, weights=W)
        b = np.unravel_index(np.argmax(need), need.shape)  # (order, mode) that needs the largest shift
        i_need = int(np.argmin(dist[b[0], :, b[1]]))  # where that mode comes closest to that line
        unstable = [float(v) for v in r[~np.all(np.isfinite(F), axis=1)]]
        out.append(dict(
            objective=problem.objectives.index(o), orders=list(o.orders), rpm=list(o.rpm), margin_hz=o.margin_hz,
            modes=[k + 1 for k in modes], n_modes_checked=int(freqs.shape[1]), crossings=cx,
            clear=bool(np.max(need) <= o.tolerance_hz and not unstable), tolerance_hz=o.tolerance_hz,
            **_closest(dist, a, r, idx, label_at),
            max_need_hz=float(np.max(need)), need_mode=int(b[1]) + 1, need_order=float(o.orders[b[0]]),
            need_label=label_at(idx[i_need])[b[1]],
            unstable_rpm=unstable,
        ))
    return out


def _closest(dist, a, r, idx, label_at) -> dict:
    """closest_hz, closest_mode, closest_label, closest_rpm of a watched mode to an order line (None: none watched)."""
    if not np.isfinite(dist[a]):
        return dict(closest_hz=None, closest_mode=None, closest_label=None, closest_rpm=None)
    return dict(closest_hz=float(dist[a]), closest_mode=int(a[2]) + 1, closest_label=label_at(idx[a[1]])[a[2]],
                closest_rpm=float(r[a[1]]))


def _band_grid(problem: Problem, n: int = 41) -> np.ndarray:
    """Speeds (rpm) for the before/after Campbell diagrams: 0 to 1.25 x the highest band end,
    plus a fine grid inside each band."""
    bands = _bands(problem)
    top = max(o.rpm[1] for o in bands) * 1.25
    grid = [np.linspace(0.0, top, n)] + [np.linspace(o.rpm[0], o.rpm[1], 21) for o in bands]
    return np.unique(np.round(np.concatenate(grid), 9))


def relevant_modes(problem: Problem, *freqs) -> int:
    """Number of lowest modes worth a Campbell diagram: those below 1.5 x the highest order line
    (plus margin) of any band in any of the frequency tables ``freqs`` ((speeds, modes) Hz,
    sorted per speed), plus two."""
    bands = _bands(problem)
    if not bands:
        return 0
    limit = 1.5 * max(max(o.orders) * o.rpm[1] / 60.0 + o.margin_hz for o in bands)
    return max(int(np.max(np.sum(np.asarray(F) < limit, axis=1))) for F in freqs) + 2


def _static_result(scene: Scene, m: dict) -> statics.StaticResult:
    """A :class:`beltjax.statics.StaticResult` from :func:`measures` (numpy) for reports and plots."""
    order = scene.route.order
    inst = m["inst"]
    hub = np.asarray(m["hub_N"])
    res = statics.StaticResult(
        span_names=drive.span_names(scene), span_tensions_N=np.asarray(m["tensions_N"]),
        span_lengths_m=np.asarray(m["span_lengths_m"]), belt_length_m=float(inst.belt_length),
        installation_tension_N=float(inst.tension), stretch=float(inst.stretch),
        hub_forces_N={order[i]: hub[i] for i in range(len(order))},
        wrap_angles_deg={order[i]: float(m["wrap_deg"][i]) for i in range(len(order))},
        speed_m_s=float(drive.belt_speed(scene)), tensioner_angle_deg=None, spring_moment_Nm=None,
        tensioner_pivot_force_N=None, iterations=0, qi=np.asarray(m["qi"]), q=np.asarray(m["q"]), inst=inst,
    )
    if scene.tensioner is not None:
        th = float(m["arm_deg"])
        res.tensioner_angle_deg = th
        res.spring_moment_Nm = float(drive.spring_moment(math.radians(th), scene))
        res.tensioner_pivot_force_N = static_state.tensioner_pivot_force(scene, hub)
    return res


def mode_labels(scene: Scene, qi, inst, rpm: float) -> list[str] | None:
    """Labels of the modes of ``scene`` about the equilibrium (qi, inst) at drive-pulley speed
    ``rpm``, in the sorted order of the modes the optimisation uses (gyroscopic with the
    ``transport`` effect and a moving belt); None if unstable there.

    Kind and span(s) are those of :func:`beltjax.drive_modal.label_modes` on these modes (their
    kinetic-energy shares: the same split as the "span" selection); a transverse or longitudinal
    mode's ordinal counts, in frequency order, the modes of its kind and span(s) (the half-wave
    count of a gyroscopic mode's shape can be one too high: its travelling phase makes an
    apparent node).  Before issue 20 the labels came from the real shapes of (M, K) without the
    gyroscopic coupling, which sort differently where a span mode passes another one, and then
    named the wrong mode.
    """
    sc = drive.canonical(scene)
    v = float(drive.belt_speed(sc, rpm))
    qi = jnp.asarray(qi)
    out = drive_modal.modes_at(sc, qi, inst, v, effects_of(sc).moving_belt and v != 0.0)
    if not bool(out["stable"]):
        return None
    labels, _ = drive_modal.label_modes(out["freqs"], out["shapes"], qi, sc, inst, out["J"])
    seen, named = {}, []
    for lab in labels:
        _, _, rest = lab.partition(" ")
        if rest.startswith(("transverse", "longitudinal")):
            seen[rest] = seen.get(rest, 0) + 1
            lab = f"{modal.ordinal(seen[rest])} {rest}"
        named.append(lab)
    return named


def check(scene: Scene, problem: Problem, evaluate: Callable, n_modes: int | None = None) -> dict:
    """Statics, Campbell diagram, constraint and resonance reports and loss terms of ``scene``
    (its own mesh).

    evaluate(rpm) -> :func:`measures` (numpy) of ``scene`` at speeds ``rpm`` (an array of
    len(:func:`sample_rpm`)); the Campbell grid is evaluated in chunks of that length, with
    each mode's span weight at each grid speed (the "span" selection) and labels where a mode is
    reported.  n_modes: lowest modes kept in the diagram (default 20).  The loss terms use the
    exact max over the sampled speeds.  Returns a dict: statics (StaticResult), campbell
    (CampbellResult or None), labels (per band, at its lowest speed), masks, constraints,
    resonance, overlaps, span_force_min_N, terms, loss.  Raises OptimizeError when the layout
    cannot be built or run on this mesh.
    """
    from beltjax import campbell

    rpm = sample_rpm(problem)
    m = evaluate(rpm)
    if not bool(m["feasible"]):
        raise OptimizeError("the layout is infeasible on the scene's mesh (the belt cannot be fitted, no static "
                            "equilibrium, unstable in the speed band, or a span past its critical speed)", "scene")
    n = drive.n_independent(scene)
    masks = problem_masks(scene, problem)
    cb, res, labels = None, [], []
    if rpm.size:
        labels = [mode_labels(scene, m["qi_speeds"][k], m["inst"], float(rpm[k])) for k in _band_starts(problem)]
        grid = _band_grid(problem)
        k = rpm.size
        F, W, good, Q = [], [], [], []
        for s in range(0, grid.size, k):
            part = grid[s:s + k]
            mc = evaluate(np.concatenate([part, np.full(k - part.size, part[-1])]))
            F.append(np.asarray(mc["freqs_hz"])[:part.size])
            W.append(np.asarray(mc["span_weights"])[:part.size])
            good.append(np.asarray(mc["good"])[:part.size])
            Q.append(np.asarray(mc["qi_speeds"])[:part.size])
        F, W, good, Q = (np.concatenate(a) for a in (F, W, good, Q))
        F = np.where(good[:, None], F, np.nan)
        first = labels[0] or ["unstable"] * n
        keep = min(n, n_modes or 20)
        orders = tuple(sorted({k for o in _bands(problem) for k in o.orders}))
        cb = campbell.CampbellResult(
            rpm=grid, frequencies_hz=F[:, :keep], labels=first[:keep], orders=orders,
            crossings=campbell.crossings(grid, F[:, :keep], orders, first[:keep]), stable=good, converged=good,
            drive_pulley=scene.route.order[drive.drive_pulley(scene)], transport=effects_of(scene).moving_belt,
        )

        @functools.lru_cache(maxsize=None)
        def label_at(i):
            return mode_labels(scene, Q[i], m["inst"], float(grid[i])) or ["unstable"] * n

        res = resonance_report(grid, F, label_at, problem, masks, W)
    terms = _floats(terms_from_measures(m, scene, problem, masks, rpm, soft=False))
    return dict(statics=_static_result(scene, m), campbell=cb, labels=labels, masks=masks,
                constraints=constraint_report(m, scene, problem), resonance=res, overlaps=overlaps(m, scene),
                span_force_min_N=float(np.min(m["span_force_N"])), terms=terms, loss=float(sum(terms.values())))


def unmet(chk: dict) -> list[dict]:
    """What a checked layout (:func:`check`) misses of the goal (:mod:`beltjax.optimize.goal`):
    a list of dicts {what, by, unit, text}, empty when the goal is met.  ``by``: how far off
    (a constraint's violation beyond its tolerance, the shift a band's mode still needs, Hz)."""
    out = []
    for a, b, g in chk["overlaps"]:
        out.append(dict(what="geometry", by=-g, unit="m", text=f"pulleys {a} and {b} overlap by {-g * 1e3:.3g} mm"))
    for c in chk["constraints"]:
        if not c["satisfied"]:
            name = f"constraint[{c['constraint']}] {c['kind']}"
            out.append(dict(what=name, by=c["violation"] - c["tolerance"], unit=c["unit"],
                            text=f"{name}: {_describe_constraint(c)} not met: {_value_text(dict(c, satisfied=True))} "
                                 f"{c['unit']}, violated by {c['violation']:.3g} {c['unit']} (tolerance "
                                 f"{c['tolerance']:g} {c['unit']})"))
    for r in chk["resonance"]:
        if r["clear"]:
            continue
        name = f"objective[{r['objective']}] resonance_band"
        cx = r["crossings"]
        parts = [f"{len(cx)} crossing{'' if len(cx) == 1 else 's'} of a watched mode with an order line"
                 + "".join(f"; mode {c['mode']} ({c['label']}) x {c['order']:g}x at {c['rpm']:.0f} rpm, "
                           f"{c['frequency_hz']:.1f} Hz" for c in cx[:3]) + ("; ..." if len(cx) > 3 else "")] if cx else []
        if r["max_need_hz"] > 0:
            parts.append(f"mode {r['need_mode']} ({r['need_label']}) needs a shift of {r['max_need_hz']:.3g} Hz to "
                         f"clear the {r['need_order']:g}x line by the {r['margin_hz']:g} Hz margin (tolerance "
                         f"{r['tolerance_hz']:g} Hz)")
        if r["unstable_rpm"]:
            parts.append(f"unstable at {', '.join(f'{v:.0f}' for v in r['unstable_rpm'][:3])} rpm")
        text = f"{name} ({r['rpm'][0]:g}-{r['rpm'][1]:g} rpm): " + "; ".join(parts)
        out.append(dict(what=name, by=r["max_need_hz"], unit="Hz", text=text))
    return out


def evaluator(scene: Scene, problem: Problem, x, result: OptimizeResult | None = None) -> Callable:
    """evaluate(rpm) -> measures (numpy) of ``scene`` at parameter values x, for :func:`check`:
    through the optimisation's compiled function when ``scene`` has the working mesh (no new
    compilation), else a forward-only compiled :func:`measures` on the scene's mesh."""
    sc = drive.canonical(scene)
    x = np.asarray(x, float)
    if result is not None and sc.model == result.working.model:
        vg = _compiled(_loss_key(problem))
        masks = jnp.asarray(problem_masks(sc, problem))

        def evaluate(rpm):
            (_, (_, m)), _ = vg(jnp.asarray(x / problem.scales), sc, jnp.asarray(rpm, float), masks)
            return jax.tree.map(np.asarray, m)
    else:
        fn = _measures_jit(_loss_key(problem))

        def evaluate(rpm):
            return jax.tree.map(np.asarray, fn(sc, jnp.asarray(x), jnp.asarray(rpm, float)))

    return evaluate
