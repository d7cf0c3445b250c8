"""One least-squares layer for the fits (damping, tensile, modal): optimistix's
Levenberg-Marquardt, run as one compiled loop that also records the loss per step.

The damping, tensile and modal fits each had a hand-written Levenberg-Marquardt loop; they now
all call :func:`solve`.  Its parts:

- the solver is ``optimistix.LevenbergMarquardt`` (a trust-region-controlled damping of the
  Gauss-Newton step, QR for the damped normal equations by lineax);
- optimistix damps isotropically, so the problem is solved in scaled coordinates
  y = scale * x (``scale`` per unknown, e.g. the Jacobian's column norms at the start: Jacobi
  scaling, what Marquardt's diagonal did in the loops it replaces);
- the loop is the solver's own ``init`` / ``step`` / ``terminate`` in a ``lax.while_loop``
  (what ``optimistix.least_squares`` runs), written out here to record 1/2 |r|^2 after every
  step for the convergence plots and to report progress through a host callback.  It is a pure
  function of arrays: it vmaps (the tensile fit runs 8 starts at once) and it compiles once per
  residual function and shapes (:func:`solve` is ``equinox.filter_jit``-ed; the residual must be
  a module-level function so that like fits share the compilation).

It stops when optimistix's Cauchy test holds (the step and the change of every residual below
``atol + rtol * |value|``), when asked when the Gauss-Newton step can gain no more than a given
fraction of the loss, or after ``max_steps``.  The second rule is the modal fit's: its
frequencies carry the statics' and eigen-solver's rounding, the loss reaches that floor in 2-3
steps, and then every trial is rejected while the trust region shrinks (measured on the bench
dataset: 18-29 steps, 38 s, against 3 steps with the gain rule; same optimum).
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import optimistix as optx

#: listeners of the progress callback (step, loss); set by :func:`reporting`
_LISTENERS: list[Callable[[int, float], None]] = []


class Solution(NamedTuple):
    """Result of :func:`solve`: the unknowns, 1/2 |r|^2 after each step (the entries after the
    last step repeat its value), the number of steps taken, whether a stop rule held, and the
    residuals and their Jacobian d r / d x at the returned x."""

    x: jax.Array
    loss: jax.Array
    steps: jax.Array
    converged: jax.Array
    residual: jax.Array
    jacobian: jax.Array


@eqx.filter_jit
def _value_and_jacobian(residual, y, inner, scale):
    """r(y / scale, inner) and its Jacobian d r / d y, by one forward pass (the value rides along
    as aux).  Jitted on its own so that the solver's three traces of the residual (the output
    structure, the solver's init and its step) share one trace: through the modal fit's statics
    and eigenvalues a trace costs seconds."""

    def value_twice(v):
        out = residual(v / scale, inner)
        return out, out

    J, val = jax.jacfwd(value_twice, has_aux=True)(y)
    return val, J


def _dense_jvp(residual, y, inner, scale):
    """r(y / scale, inner) whose linearisation is the dense Jacobian times the tangent.

    optimistix linearises the residual (``jax.linearize``) and its linear solves materialise that
    linear map column by column, once per solve (2-3 per step).  Through the modal fit's statics
    and eigenvalues each materialisation replays the whole tangent program; with the Jacobian
    formed once by ``jacfwd`` (all tangents in one pass) and stored, a materialisation is a
    matrix product.  Measured on the bench modal dataset: the whole fit 2.9 s without, 1.9 s
    with (benchmarks/results/least_squares.json)."""

    @jax.custom_jvp
    def g(y):
        return _value_and_jacobian(residual, y, inner, scale)[0]

    @g.defjvp
    def g_jvp(primals, tangents):
        (yp,), (ty,) = primals, tangents
        val, J = _value_and_jacobian(residual, yp, inner, scale)
        return val, J @ ty

    return g(y)


class _Scaled(eqx.Module):
    """r(y / scale, args) as optimistix wants it: fn(y, args) -> (residuals, aux)."""

    residual: Callable = eqx.field(static=True)

    def __call__(self, y, args):
        inner, scale = args
        return _dense_jvp(self.residual, y, inner, scale), None


def _host_report(step, loss):
    for f in _LISTENERS:
        f(int(step), float(loss))


class reporting:
    """Context manager: ``with reporting(fn): solve(..., report=True)`` calls fn(step, loss)
    on the host after every step (for progress lines)."""

    def __init__(self, fn: Callable[[int, float], None]):
        self.fn = fn

    def __enter__(self):
        _LISTENERS.append(self.fn)
        return self

    def __exit__(self, *exc):
        _LISTENERS.remove(self.fn)


def solve(residual: Callable, x0: jax.Array, args, scale: jax.Array, max_steps, *, history: int,
          rtol: float, atol: float, gain_rtol: float | None = None, report: bool = False) -> Solution:
    """Minimise 1/2 |residual(x, args)|^2 from x0 by optimistix's Levenberg-Marquardt in the
    coordinates y = scale * x (``scale`` > 0, one per unknown; units of 1/x).  Pure and
    vmappable; see the module docstring for the stop rule and the loss history.
    ``max_steps`` (an int or an integer array, at most ``history``) is traced: ``max_steps = 0``
    evaluates the residuals and Jacobian at x0 with the same compiled program.  With
    ``gain_rtol`` it also stops when the undamped Gauss-Newton step could lower the loss by no
    more than ``gain_rtol`` of it (a loss at the residuals' noise floor, where a trust region
    would otherwise shrink through many rejected steps)."""
    return _solve(residual, x0, args, scale, jnp.asarray(max_steps), history=history, rtol=rtol, atol=atol,
                  gain_rtol=gain_rtol, report=report)


@eqx.filter_jit
def _solve(residual, x0, args, scale, max_steps, *, history, rtol, atol, gain_rtol, report):
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol)
    fn = _Scaled(residual)
    a = (args, scale)
    y0 = x0 * scale
    f_struct = jax.eval_shape(lambda: fn(y0, a)[0])
    tags = frozenset()
    state0 = solver.init(fn, y0, a, {}, f_struct, None, tags)
    dyn0, static = eqx.partition(state0, eqx.is_array)
    hist0 = jnp.zeros(history + 1)
    max_steps = jnp.minimum(jnp.asarray(max_steps), history)

    def cond(c):
        _, _, k, done, _ = c
        return (~done) & (k < max_steps + 1)

    def body(c):
        y, dyn, k, _, hist = c
        state = eqx.combine(static, dyn)
        y, state, _ = solver.step(fn, y, a, {}, state, tags)
        done, _ = solver.terminate(fn, y, a, {}, state, tags)
        r = state.f_info.residual  # at y, the last accepted point
        loss = 0.5 * jnp.sum(r**2)
        if gain_rtol is not None:
            # what the undamped Gauss-Newton step could still gain: 1/2 |J d|^2, d = argmin |J d + r|
            d = lx.linear_solve(state.f_info.jac, -r, lx.QR(), throw=False).value
            gain = 0.5 * jnp.sum(state.f_info.jac.mv(d) ** 2)
            done = done | (gain <= gain_rtol * loss)
        if report:
            jax.debug.callback(_host_report, k, loss)
        dyn = eqx.filter(state, eqx.is_array)
        return y, dyn, k + 1, done, hist.at[k].set(loss)

    y, dyn, k, done, hist = jax.lax.while_loop(cond, body, (y0, dyn0, jnp.asarray(0), jnp.asarray(False), hist0))
    # the first step evaluates the start (it is always accepted): the history's first entry is the
    # starting loss, then one entry per Levenberg-Marquardt step
    last = hist[jnp.maximum(k - 1, 0)]
    hist = jnp.where(jnp.arange(history + 1) < k, hist, last)
    f_info = eqx.combine(static, dyn).f_info
    J = f_info.jac.as_matrix() * scale[None, :]  # d r / d x = d r / d y * scale
    return Solution(y / scale, hist, jnp.maximum(k - 1, 0), done, f_info.residual, J)


def column_scale(jac: jax.Array) -> jax.Array:
    """Jacobi scaling: the Jacobian's column norms (residual units per unit of x), 1 where a
    column is zero or not finite."""
    d = jnp.linalg.norm(jac, axis=0)
    return jnp.where(jnp.isfinite(d) & (d > 0), d, 1.0)
