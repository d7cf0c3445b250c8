"""The optimiser: Adam on the scaled variables, projected onto the bounds, with rejected steps."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np
import optax

from beltjax import drive, parameters
from beltjax.scene import Scene
from beltjax.optimize.loss import _compiled, _labels_and_masks, _loss_key
from beltjax.optimize.problem import OptimizeError, Problem, _bands, sample_rpm, working_scene


@dataclass
class OptimizeResult:
    """Outcome of :func:`optimise` (file units).

    paths, x0, x (best feasible values met), lower, upper; loss0, loss (total);
    terms0, terms (name -> value); measures0, measures (:func:`measures` at x0 and x, numpy,
    working mesh); labels (per resonance objective, at its lowest speed, at x0); masks (the
    mode selection); history: per accepted step {step, loss, x, learning_rate, t_s (s since the
    start)}; rejected:
    steps rejected (infeasible or non-finite) with the learning rate halved; steps: optimiser
    steps taken; converged, reason; wall_s (s, with compilation); compile_s (s, the first
    value-and-gradient call); scene: the optimised scene (the input's mesh); problem;
    working: the scene optimised on.
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
    labels: list
    masks: np.ndarray
    history: list[dict]
    rejected: int
    steps: int
    converged: bool
    reason: str
    wall_s: float
    compile_s: float
    scene: Scene = field(repr=False)
    problem: Problem = field(repr=False)
    working: Scene = field(repr=False)

    @property
    def loss_history(self) -> list[float]:
        """Total loss after each accepted step (the start first)."""
        return [h["loss"] for h in self.history]


def _floats(d: dict) -> dict:
    return {k: float(v) for k, v in d.items()}


def _decay(step: int, steps: int) -> float:
    """Cosine decay of the learning rate from 1 to 0.1 over the step budget (damps Adam's
    oscillation about a kink or an active penalty)."""
    return 0.1 + 0.45 * (1.0 + math.cos(math.pi * min(step, steps) / steps))


def optimise(scene: Scene, problem: Problem, progress: Callable[[dict], None] | None = None) -> OptimizeResult:
    """Minimise the problem's loss over its variables from the scene's values.

    Adam on x / scale, projected onto the bounds; a step whose layout is infeasible or whose
    loss or gradient is not finite is rejected and the learning rate halved (after 30
    rejections in a row the run stops).  Stops after ``problem.steps`` steps, or earlier when
    the best loss has not fallen by ``tolerance`` (relative) in ``patience`` steps or is 0.
    progress: optional callable(dict(step, steps, loss, best, learning_rate, rejected)).
    Returns the best feasible point met (never NaN).
    """
    t_start = time.perf_counter()
    work = working_scene(scene, problem)
    scales = problem.scales
    lo = np.array([v.lower for v in problem.variables]) / scales
    hi = np.array([v.upper for v in problem.variables]) / scales
    x0 = np.array([float(parameters.get_value(scene, p)) for p in problem.paths])
    vg = _compiled(_loss_key(problem))
    rpm = jnp.asarray(sample_rpm(problem))
    n = drive.n_independent(work)
    masks = jnp.ones((len(_bands(problem)), n))  # provisional: the labels need a first evaluation

    def evaluate(z):
        (val, (terms, m)), g = vg(jnp.asarray(z), work, rpm, masks)
        val, g = float(val), np.asarray(g)
        good = bool(m["feasible"]) and math.isfinite(val) and bool(np.all(np.isfinite(g)))
        return good, val, g, (_floats(terms), jax.tree.map(np.asarray, m))

    z = x0 / scales
    t0 = time.perf_counter()
    good, val, g, (terms, m0) = evaluate(z)
    compile_s = time.perf_counter() - t0
    if not bool(m0["feasible"]):
        raise OptimizeError("the starting layout is infeasible (the belt cannot be fitted, no static equilibrium, "
                            "or unstable in the speed band)", "scene")
    labels = []
    if _bands(problem):
        labels, masks_np = _labels_and_masks(work, problem, m0)
        masks = jnp.asarray(masks_np)
        good, val, g, (terms, m0) = evaluate(z)
    if not good:
        raise OptimizeError("the loss or its gradient is not finite at the starting layout", "scene")
    terms0 = terms
    opt = optax.scale_by_adam()
    state = opt.init(jnp.asarray(z))
    best = (val, z.copy(), terms, m0)
    history = [dict(step=0, loss=val, x=list(z * scales), learning_rate=problem.learning_rate,
                    t_s=time.perf_counter() - t_start)]
    lr, rejected, in_a_row, since_best, step = problem.learning_rate, 0, 0, 0, 0
    reason, converged = "step limit reached", False
    while step < problem.steps:
        if best[0] <= 0.0:
            reason, converged = "loss is 0: every objective met", True
            break
        upd, new_state = opt.update(jnp.asarray(g), state)
        rate = lr * _decay(step, problem.steps)
        z_new = np.clip(z - rate * np.asarray(upd), lo, hi)
        ok, v_new, g_new, t_new = evaluate(z_new)
        step += 1
        if not ok:
            rejected += 1
            in_a_row += 1
            lr *= 0.5
            if in_a_row >= 30:
                reason = "30 rejected steps in a row (infeasible neighbourhood)"
                break
        else:
            in_a_row = 0
            z, g, state, val = z_new, g_new, new_state, v_new
            history.append(dict(step=step, loss=val, x=list(z * scales), learning_rate=rate,
                                t_s=time.perf_counter() - t_start))
            if val < best[0] - problem.tolerance * abs(best[0]):
                since_best = 0
            else:
                since_best += 1
            if val < best[0]:
                best = (val, z.copy(), *t_new)
            if since_best >= problem.patience:
                reason = f"no relative improvement above {problem.tolerance:g} in {problem.patience} steps"
                converged = True
                break
        if progress is not None:
            progress(dict(step=step, steps=problem.steps, loss=val, best=best[0], learning_rate=rate,
                          rejected=rejected))
    x = best[1] * scales
    out_scene = parameters.set_values(scene, dict(zip(problem.paths, (float(v) for v in x))))
    return OptimizeResult(
        paths=problem.paths, x0=x0, x=x, lower=lo * scales, upper=hi * scales,
        loss0=history[0]["loss"], loss=best[0], terms0=terms0, terms=best[2], measures0=m0, measures=best[3],
        labels=labels, masks=np.asarray(masks), history=history, rejected=rejected, steps=step,
        converged=converged, reason=reason, wall_s=time.perf_counter() - t_start, compile_s=compile_s,
        scene=out_scene, problem=problem, working=work,
    )
