"""Reports on a layout: constraints, resonance bands, and the check on the scene's own mesh."""

from __future__ import annotations

import math
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from beltjax import drive, statics
from beltjax.scene import TENSIONER, Scene
from beltjax.optimize.loss import (_compiled, _labels_and_masks, _loss_key, _measures_jit, _violations, band_need,
                                   terms_from_measures)
from beltjax.optimize.problem import _UNIT_NAME, OptimizeError, Problem, _bands, sample_rpm
from beltjax.optimize.solver import OptimizeResult, _floats


def constraint_report(m: dict, scene: Scene, problem: Problem) -> list[dict]:
    """Each constraint's value, worst violation (its units) and whether it holds within its
    tolerance, from :func:`measures`-like numpy values ``m``."""
    out = []
    for j, c in enumerate(problem.constraints):
        viol, value = _violations(c, {k: np.asarray(m[k]) for k in ("wrap_deg", "tensions_N", "arm_deg", "gaps_m")},
                                  scene, np)
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
    what = "span tension" + (f" {c['where']}" if c["where"] else "") if c["kind"] == "static_tension" else "arm angle"
    lo = "" if c["lower"] is None else f"{c['lower']:g} <= "
    hi = "" if c["upper"] is None else f" <= {c['upper']:g}"
    return f"{lo}{what}{hi} {u}"


def _value_text(c: dict) -> str:
    v = c["value"]
    fmt = (lambda x: f"{x:.4g}") if c["kind"] != "no_overlap" else (lambda x: f"{x:.4f}")  # noqa: E731
    text = f"{fmt(v[0])}..{fmt(v[1])}" if isinstance(v, list) else fmt(v)
    return text + ("" if c["satisfied"] else f" (violated by {c['violation']:.3g})")


def resonance_report(rpm, freqs, labels, problem: Problem, masks) -> list[dict]:
    """Per resonance objective, from a Campbell sweep (rpm (n,), freqs (n, m) Hz, labels (m,)):
    crossings of the watched modes (``masks``, :func:`mode_masks`) with the order lines inside
    the band, the closest approach (Hz) of a watched mode to an order line in the band, and the
    largest shift still needed (Hz, exact max over the band's speeds of the sweep)."""
    from beltjax import campbell

    rpm, freqs = np.asarray(rpm, float), np.asarray(freqs, float)
    out = []
    for j, o in enumerate(_bands(problem)):
        modes = [k for k in np.flatnonzero(np.asarray(masks)[j]) if k < freqs.shape[1]]
        inside = (rpm >= o.rpm[0] - 1e-9) & (rpm <= o.rpm[1] + 1e-9)
        cx = [c for c in campbell.crossings(rpm[inside], freqs[inside], o.orders, labels)
              if c["mode"] - 1 in modes]
        F = freqs[inside][:, modes]
        g = F[None] - np.asarray(o.orders)[:, None, None] * rpm[inside][None, :, None] / 60.0
        need = band_need(F, rpm[inside], np.asarray(o.orders), o.margin_hz, soft=False)
        a = np.unravel_index(np.nanargmin(np.abs(g)), g.shape)
        out.append(dict(
            objective=problem.objectives.index(o), orders=list(o.orders), rpm=list(o.rpm), margin_hz=o.margin_hz,
            modes=[int(k) + 1 for k in modes], n_modes_checked=int(freqs.shape[1]), crossings=cx,
            clear=bool(np.nanmax(need) <= 0.0), closest_hz=float(np.abs(g[a])), closest_mode=int(modes[a[2]]) + 1,
            closest_label=labels[modes[a[2]]], closest_rpm=float(rpm[inside][a[1]]),
            max_need_hz=float(np.nanmax(need)),
        ))
    return out


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
        pivot = hub[order.index(TENSIONER)].copy()
        if scene.model.has("gravity"):
            t = scene.tensioner
            pivot[1] += drive.GRAVITY[1] * float(t.arm_mass + t.pulley_mass)
        res.tensioner_pivot_force_N = [float(pivot[0]), float(pivot[1])]
    return res


def check(scene: Scene, problem: Problem, evaluate: Callable, n_modes: int | None = None) -> dict:
    """Statics, Campbell diagram, constraint report and loss terms of ``scene`` (its own mesh).

    evaluate(rpm) -> :func:`measures` (numpy) of ``scene`` at speeds ``rpm`` (an array of
    len(:func:`sample_rpm`)); the Campbell grid is evaluated in chunks of that length.
    n_modes: lowest modes kept in the diagram (default 20).  The loss terms use the exact max
    over the sampled speeds.  Returns a dict: statics (StaticResult), campbell (CampbellResult
    or None), labels, masks, constraints, resonance, terms, loss.
    """
    from beltjax import campbell

    rpm = sample_rpm(problem)
    m = evaluate(rpm)
    if not bool(m["feasible"]):
        raise OptimizeError("the layout is infeasible on the scene's mesh", "scene")
    n = drive.n_independent(scene)
    cb, res, labels, masks = None, [], [], np.zeros((0, n))
    if rpm.size:
        labels, masks = _labels_and_masks(scene, problem, m)
        grid = _band_grid(problem)
        k = rpm.size
        F, good = [], []
        for s in range(0, grid.size, k):
            part = grid[s:s + k]
            mc = evaluate(np.concatenate([part, np.full(k - part.size, part[-1])]))
            F.append(np.asarray(mc["freqs_hz"])[:part.size])
            good.append(np.asarray(mc["good"])[:part.size])
        F, good = np.concatenate(F), np.concatenate(good)
        F = np.where(good[:, None], F, np.nan)
        keep = min(n, n_modes or 20)
        orders = tuple(sorted({k for o in _bands(problem) for k in o.orders}))
        cb = campbell.CampbellResult(
            rpm=grid, frequencies_hz=F[:, :keep], labels=labels[0][:keep], orders=orders,
            crossings=campbell.crossings(grid, F[:, :keep], orders, labels[0][:keep]), stable=good, converged=good,
            drive_pulley=scene.route.order[drive.drive_pulley(scene)], transport=scene.model.has("transport"),
        )
        res = resonance_report(grid, F, labels[0], problem, masks)
    terms = _floats(terms_from_measures(m, scene, problem, masks, rpm, soft=False))
    return dict(statics=_static_result(scene, m), campbell=cb, labels=labels, masks=masks,
                constraints=constraint_report(m, scene, problem), resonance=res, terms=terms,
                loss=float(sum(terms.values())))


def evaluator(scene: Scene, problem: Problem, x, result: OptimizeResult | None = None) -> Callable:
    """evaluate(rpm) -> measures (numpy) of ``scene`` at parameter values x, for :func:`check`:
    through the optimisation's compiled function when ``scene`` has the working mesh (no new
    compilation), else a forward-only compiled :func:`measures` on the scene's mesh."""
    sc = drive.canonical(scene)
    x = np.asarray(x, float)
    if result is not None and sc.model == result.working.model:
        vg = _compiled(_loss_key(problem))
        masks = jnp.asarray(result.masks)

        def evaluate(rpm):
            (_, (_, m)), _ = vg(jnp.asarray(x / problem.scales), sc, jnp.asarray(rpm, float), masks)
            return jax.tree.map(np.asarray, m)
    else:
        fn = _measures_jit(_loss_key(problem))

        def evaluate(rpm):
            return jax.tree.map(np.asarray, fn(sc, jnp.asarray(x), jnp.asarray(rpm, float)))

    return evaluate
