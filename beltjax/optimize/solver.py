"""The optimiser: Adam on the scaled variables, projected onto the bounds, from one or more starts.

Each start runs Adam (optax) on z = x / scale from its point, with the learning rate decayed
along a cosine to a tenth over ``steps``, a step projected onto the bounds (clip).  A step to a
layout that cannot be built or run (the belt cannot be fitted, no equilibrium, unstable, a span
past its critical speed, a non-finite loss or gradient) is rejected and the learning rate
halved; after 30 rejections in a row the start ends.  A start also ends after ``steps`` steps,
when its loss is 0, or when :class:`beltjax.optimize.stop.StopRule` finds it stalled.

Starts.  The first start is the scene's values.  If a start ends without any step meeting the
goal (:func:`beltjax.optimize.goal.layout_status`: feasible, every constraint within its
tolerance, every band clear), the next one begins, up to ``starts``: the candidates are the
first CANDIDATES points of the Halton sequence over the bounds (bases 2, 3, 5, ... one per
variable, in the order of the file), each evaluated once; the valid ones (built and run, no
overlapping pulleys) are taken in the order of :func:`~beltjax.optimize.goal.rank` (goal met
first, then feasible, then least constraint excess; the loss; the Halton index).  So the starts
are deterministic: the same file and scene give the same run.

The result is the best step of every start by :func:`~beltjax.optimize.goal.rank`: a layout
that meets the goal if any step did, else a feasible one, else (only when no evaluated layout
met every constraint, the start included) the one nearest to it; never an overlapping layout or
one that cannot be built.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np
import optax

from beltjax import parameters
from beltjax.scene import Scene, require_scene
from beltjax.optimize.goal import layout_status, overlaps, rank
from beltjax.optimize.loss import WATCHED, _compiled, _loss_key, band_weights, problem_masks
from beltjax.optimize.problem import OptimizeError, Problem, _band_starts, _bands, sample_rpm, working_scene
from beltjax.optimize.stop import StopRule

#: Halton points evaluated as candidates for the starts after the first
CANDIDATES = 8
#: rejected steps in a row that end a start
MAX_REJECTED = 30


@dataclass
class OptimizeResult:
    """Outcome of :func:`optimise` (file units).

    paths, x0, x (the result: the best step, module docstring), lower, upper; loss0, loss
    (total); terms0, terms (name -> value); measures0, measures (:func:`measures` at x0 and x,
    numpy, working mesh); status0, status (:func:`~beltjax.optimize.goal.layout_status` there);
    masks (the mode selection); history: per accepted step and per start point {step (counted
    over every start), start, loss, x, learning_rate, t_s (s since the beginning), valid,
    feasible, goal}; starts: per start {start, x0, steps, rejected, reason, best_loss,
    goal_met}; best_index (the result's place in the history); rejected: steps rejected with the
    learning rate halved; steps: optimiser steps taken (every start); converged (the last
    start ended by the stop rule or a zero loss), reason (the last start's); goal_met (the
    result meets the goal on the working mesh at the sampled speeds; the final word is the
    check on the scene's own mesh); wall_s (s, with compilation); compile_s (s, the first
    value-and-gradient call); scene: the optimised scene (the input's mesh); problem; working:
    the scene optimised on.
    """

    paths: list[str]
    x0: np.ndarray
    x: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    loss0: float
    loss: float
    terms0: dict
    terms: dict
    measures0: dict
    measures: dict
    status0: dict
    status: dict
    masks: np.ndarray
    history: list[dict]
    starts: list[dict]
    best_index: int
    rejected: int
    steps: int
    converged: bool
    reason: str
    goal_met: bool
    wall_s: float
    compile_s: float
    scene: Scene = field(repr=False)
    problem: Problem = field(repr=False)
    working: Scene = field(repr=False)

    @property
    def loss_history(self) -> list[float]:
        """Total loss after each accepted step (each start's point included, the first first)."""
        return [h["loss"] for h in self.history]


def _floats(d: dict) -> dict:
    return {k: float(v) for k, v in d.items()}


def _decay(step: int, steps: int) -> float:
    """Cosine decay of the learning rate from 1 to 0.1 over the step budget (damps Adam's
    oscillation about a kink or an active penalty): optax's cosine schedule,
    0.1 + 0.45 (1 + cos(pi min(step, steps) / steps))."""
    return float(optax.cosine_decay_schedule(1.0, steps, alpha=0.1)(step))


def _primes(n: int) -> list[int]:
    out, k = [], 2
    while len(out) < n:
        if all(k % p for p in out if p * p <= k):
            out.append(k)
        k += 1
    return out


def halton(k: int, d: int) -> np.ndarray:
    """Point k >= 1 of the d-dimensional Halton sequence in [0, 1)^d (bases: the first d primes)."""
    out = []
    for b in _primes(d):
        f, r, i = 1.0, 0.0, k
        while i > 0:
            f /= b
            r += f * (i % b)
            i //= b
        out.append(r)
    return np.array(out)


def _check_start(problem: Problem, work: Scene, m: dict, masks) -> None:
    """OptimizeError unless the start can be built and run, no pulleys overlap, and each band
    watches at least one mode at one of its speeds."""
    if not bool(m["feasible"]):
        raise OptimizeError("the starting layout is infeasible (the belt cannot be fitted, no static equilibrium, "
                            "unstable in the speed band, or a span past its critical speed)", "scene")
    for a, b, g in overlaps(m, work):
        raise OptimizeError(f"the starting layout has pulleys {a!r} and {b!r} overlapping by {-g * 1e3:.3g} mm",
                            "scene")
    for j, (o, k) in enumerate(zip(_bands(problem), _band_starts(problem))):
        if not np.any(band_weights(m, problem, masks, j, slice(k, k + o.speeds), np) >= WATCHED):
            what = "no transverse span mode" if o.modes == "span" else "no mode"
            raise OptimizeError(f"{what} is watched at the band's speeds with modes = {o.modes!r}",
                                f"objective[{problem.objectives.index(o)}].modes")


def optimise(scene: Scene, problem: Problem, progress: Callable[[dict], None] | None = None) -> OptimizeResult:
    """Minimise the problem's loss over its variables, from the scene's values and, while the
    goal is not met, from further starts (module docstring).

    progress: optional callable(dict(start, starts, step, steps, loss, best, learning_rate,
    rejected)) after each step (``step`` counted within the start, of ``steps``).
    Returns the best step (module docstring), never NaN; raises OptimizeError when the start
    cannot be built or run, or a band watches no mode.
    """
    require_scene(scene)
    if not isinstance(problem, Problem):
        raise OptimizeError(f"problem: expected an optimisation problem (beltjax.load_problem), got "
                            f"{type(problem).__name__}", "problem")
    t_start = time.perf_counter()
    work = working_scene(scene, problem)
    scales = problem.scales
    lo = np.array([v.lower for v in problem.variables]) / scales
    hi = np.array([v.upper for v in problem.variables]) / scales
    x0 = np.array([float(parameters.get_value(scene, p)) for p in problem.paths])
    vg = _compiled(_loss_key(problem))
    rpm = jnp.asarray(sample_rpm(problem))
    masks_np = problem_masks(work, problem)
    masks = jnp.asarray(masks_np)

    def evaluate(z):
        (val, (terms, m)), g = vg(jnp.asarray(z), work, rpm, masks)
        val, g, m = float(val), np.asarray(g), jax.tree.map(np.asarray, m)
        good = bool(m["feasible"]) and math.isfinite(val) and bool(np.all(np.isfinite(g)))
        status = layout_status(m, work, problem, masks_np) if good else None
        return dict(good=good, loss=val, g=g, terms=_floats(terms), m=m, status=status, z=np.array(z, float))

    t0 = time.perf_counter()
    e0 = evaluate(x0 / scales)
    compile_s = time.perf_counter() - t0
    _check_start(problem, work, e0["m"], masks_np)
    if not e0["good"]:
        raise OptimizeError("the loss or its gradient is not finite at the starting layout", "scene")

    history, starts, candidates = [], [], None
    best, total, rejected = None, 0, 0

    def record(e, start, rate):
        nonlocal best
        st = e["status"]
        history.append(dict(step=total, start=start, loss=e["loss"], x=list(e["z"] * scales), learning_rate=rate,
                            t_s=time.perf_counter() - t_start, valid=st["valid"], feasible=st["feasible"],
                            goal=st["goal"]))
        key = rank(st, e["loss"])
        if best is None or key < best[0]:
            best = (key, len(history) - 1, e)

    reason, converged = "", False
    for s in range(problem.starts):
        if s == 0:
            e = e0
        else:
            if candidates is None:
                pts = [evaluate(lo + halton(k, lo.size) * (hi - lo)) for k in range(1, CANDIDATES + 1)]
                candidates = sorted((c for c in pts if c["good"] and c["status"]["valid"]),
                                    key=lambda c: rank(c["status"], c["loss"]))
            if not candidates:
                break
            e = candidates.pop(0)
        record(e, s, problem.learning_rate)
        rule = StopRule(problem.tolerance, problem.patience, min(problem.min_steps, problem.steps))
        rule.update(e["loss"])
        opt = optax.scale_by_adam()
        state = opt.init(jnp.asarray(e["z"]))
        lr, in_a_row, k, n_rejected = problem.learning_rate, 0, 0, 0
        reason, converged = "step limit reached", False
        while k < problem.steps:
            if e["loss"] <= 0.0:
                reason, converged = "loss is 0", True
                break
            upd, new_state = opt.update(jnp.asarray(e["g"]), state)
            rate = lr * _decay(k, problem.steps)
            new = evaluate(np.clip(e["z"] - rate * np.asarray(upd), lo, hi))
            k += 1
            total += 1
            if not new["good"]:
                n_rejected += 1
                in_a_row += 1
                lr *= 0.5
                if in_a_row >= MAX_REJECTED:
                    reason = f"{MAX_REJECTED} rejected steps in a row (infeasible neighbourhood)"
                    break
            else:
                in_a_row = 0
                e, state = new, new_state
                record(e, s, rate)
                if rule.update(e["loss"]):
                    reason, converged = rule.reason, True
                    break
            if progress is not None:
                progress(dict(start=s + 1, starts=problem.starts, step=k, steps=problem.steps, loss=e["loss"],
                              best=best[2]["loss"], learning_rate=rate, rejected=rejected + n_rejected))
        rejected += n_rejected
        mine = [h for h in history if h["start"] == s]
        starts.append(dict(start=s, x0=mine[0]["x"], steps=k, rejected=n_rejected, reason=reason,
                           best_loss=min(h["loss"] for h in mine), goal_met=any(h["goal"] for h in mine)))
        if best[2]["status"]["goal"]:
            break

    _, best_index, eb = best
    x = eb["z"] * scales
    out_scene = parameters.set_values(scene, dict(zip(problem.paths, (float(v) for v in x))))
    return OptimizeResult(
        paths=problem.paths, x0=x0, x=x, lower=lo * scales, upper=hi * scales, loss0=e0["loss"], loss=eb["loss"],
        terms0=e0["terms"], terms=eb["terms"], measures0=e0["m"], measures=eb["m"], status0=e0["status"],
        status=eb["status"], masks=masks_np, history=history, starts=starts, best_index=best_index, rejected=rejected,
        steps=total, converged=converged, reason=reason, goal_met=bool(eb["status"]["goal"]),
        wall_s=time.perf_counter() - t_start, compile_s=compile_s, scene=out_scene, problem=problem, working=work,
    )

