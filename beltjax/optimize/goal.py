"""Whether an evaluated layout meets the optimisation's goal, and which step is the result.

The goal of a run: a layout that can be built and run (the belt fitted, every equilibrium
converged and stable, no span past its critical speed, no two pulleys overlapping), with every
constraint within its tolerance and every resonance band clear of its order lines with its
margin.  The hub-load objective has no target: it is minimised, never "unmet".

The critical-speed check is :func:`beltjax.critical.span_forces` (each span's force on the
pulleys, tension - rhoA c^2 lam, > 0) at the scene's speed and every sampled speed, in
:func:`beltjax.optimize.loss.measures`: a step past it is rejected like an unstable one.
"""

from __future__ import annotations

import numpy as np

from beltjax.scene import Scene
from beltjax.optimize.loss import _violations, band_need, band_weights
from beltjax.optimize.problem import _UNIT, Problem, _band_starts, _bands, _pairs, sample_rpm


def overlaps(m: dict, scene: Scene) -> list[tuple[str, str, float]]:
    """(pulley, pulley, gap m <= 0) of every two route entries whose rims overlap, from measures ``m``."""
    order = scene.route.order
    return [(order[i], order[j], float(g)) for (i, j), g in zip(_pairs(len(order)), np.asarray(m["gaps_m"]))
            if not g > 0]


def layout_status(m: dict, scene: Scene, problem: Problem, masks, rpm=None) -> dict:
    """Verdict on one evaluated layout from numpy :func:`~beltjax.optimize.loss.measures` ``m``
    (the sampled speeds ``rpm``, default :func:`sample_rpm`).

    Returns dict: valid (built and run: ``m["feasible"]`` and no overlap), feasible (valid and
    every constraint within its tolerance), clear (every resonance band clear: the shift still
    needed, exact max over the sampled speeds, within the band's tolerance_hz), goal (feasible and clear), excess (sum over the constraints of
    (worst violation - tolerance)^+ / penalty unit: 0 when all hold), need_hz (per band, the
    largest shift still needed, Hz).
    """
    rpm = sample_rpm(problem) if rpm is None else np.asarray(rpm)
    valid = bool(m["feasible"]) and not overlaps(m, scene)
    excess = 0.0
    for c in problem.constraints:
        viol, _ = _violations(c, m, scene, np)
        worst = float(np.max(viol)) if np.size(viol) else 0.0
        excess += max(worst - c.tolerance, 0.0) / _UNIT[c.kind]
    need = []
    for j, (o, k) in enumerate(zip(_bands(problem), _band_starts(problem))):
        sl = slice(k, k + o.speeds)
        w = band_weights(m, problem, masks, j, sl, np)
        n = band_need(np.asarray(m["freqs_hz"])[sl], rpm[sl], np.asarray(o.orders), o.margin_hz, False, w)
        need.append(float(np.max(n)) if np.size(n) else 0.0)
    feasible = valid and excess == 0.0
    clear = all(n <= o.tolerance_hz for n, o in zip(need, _bands(problem)))
    return dict(valid=valid, feasible=feasible, clear=clear, goal=feasible and clear, excess=excess, need_hz=need)


def rank(status: dict, loss: float) -> tuple:
    """Sort key of a step as the result (smaller is better): goal met, then feasible, then the
    rest of the valid steps (by constraint excess); within a class the loss.  An invalid step
    (overlapping pulleys, or not buildable) ranks after every valid one."""
    if not status["valid"]:
        return (3, float("inf"), loss)
    if status["goal"]:
        return (0, loss, 0.0)
    if status["feasible"]:
        return (1, loss, 0.0)
    return (2, status["excess"], loss)
