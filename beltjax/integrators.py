"""Structural-dynamics time integrators written as diffrax solvers.

``GeneralizedAlpha`` is the generalized-alpha method for first-order systems
``y' = f(t, y)`` of Jansen, Whiting & Hulbert (2000), "A generalized-alpha
method for integrating the filtered Navier-Stokes equations with a stabilized
finite element method", CMAME 190.  Given the spectral radius at infinity
``rho_inf`` in [0, 1] it uses::

    alpha_m = (3 - rho_inf) / (2 (1 + rho_inf))
    alpha_f = 1 / (1 + rho_inf)
    gamma   = 1/2 + alpha_m - alpha_f

and advances ``(y_n, ydot_n) -> (y_{n+1}, ydot_{n+1})`` by::

    y_{n+1}         = y_n + h ydot_n + gamma h (ydot_{n+1} - ydot_n)
    ydot_{n+alpha_m} = ydot_n + alpha_m (ydot_{n+1} - ydot_n)
    y_{n+alpha_f}    = y_n + alpha_f (y_{n+1} - y_n)
    ydot_{n+alpha_m} = f(t_n + alpha_f h, y_{n+alpha_f})          (solved for ydot_{n+1})

It is second-order accurate and A-stable; ``rho_inf`` is the amplification
factor of infinitely stiff (h omega -> inf) components.  ``rho_inf = 1``
(alpha_m = alpha_f = gamma = 1/2) is exactly the implicit midpoint rule
``y_{n+1} = y_n + h f(t_n + h/2, (y_n + y_{n+1})/2)``: no numerical
dissipation, symplectic, quadratic invariants (the energy of linear
structures) conserved to round-off.  ``rho_inf < 1`` damps components with
``h omega >> 1`` (e.g. unresolved axial modes of a belt) while keeping second
order at low frequency; ``rho_inf = 0`` annihilates them in one step.

Units: the solver is unit-agnostic; ``t`` and ``h`` are in the units of the
time variable (s in beltjax), ``y`` in its own units and the Newton
tolerances ``atol`` in the units of ``y`` (``rtol`` dimensionless).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import diffrax
import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

__all__ = ["GeneralizedAlpha", "generalized_alpha_parameters"]


def generalized_alpha_parameters(rho_inf):
    """(alpha_m, alpha_f, gamma) of the first-order generalized-alpha method (JWH 2000).

    rho_inf: spectral radius at infinite step (dimensionless, 0 <= rho_inf <= 1).
    """
    alpha_m = 0.5 * (3.0 - rho_inf) / (1.0 + rho_inf)
    alpha_f = 1.0 / (1.0 + rho_inf)
    gamma = 0.5 + alpha_m - alpha_f
    return alpha_m, alpha_f, gamma


def _lu_solve(lu, perm, b):
    """A^-1 b from the LU factors of A with its row permutation (= jax.scipy.linalg.lu_solve
    with the permutation kept, same operations and round-off); b of shape (n, k)."""
    x = b[perm]
    x = jax.lax.linalg.triangular_solve(lu, x, left_side=True, lower=True, unit_diagonal=True)
    return jax.lax.linalg.triangular_solve(lu, x, left_side=True, lower=False)


class GeneralizedAlpha(diffrax.AbstractSolver):
    """Generalized-alpha method (Jansen, Whiting & Hulbert 2000) for y' = f(t, y).

    An implicit, fixed-step, second-order diffrax solver for ``diffrax.ODETerm``;
    use it with ``diffrax.ConstantStepSize`` (it has no error estimate, so
    adaptive controllers refuse it).  Dense output (``SaveAt(ts=...)``) is by
    ``diffrax.LocalLinearInterpolation``.  ``y`` may be any pytree of float
    arrays; it is flattened internally and the implicit equation for
    ``ydot_{n+1}`` is solved by Newton's method with the dense Jacobian of
    ``f`` from ``jax.jacfwd`` and a dense LU solve of the row- and
    column-equilibrated Newton matrix, so it suits systems of up to a few
    hundred unknowns.  The predictor is JWH's ``y_{n+1} = y_n``.

    The solver state is ``(ydot_n, factors, age)``: the rate (units of y per unit
    time), initialised to ``f(t0, y0)`` and re-initialised after a jump
    (``made_jump``), and the kept Newton-matrix factors with their age in steps.

    Fields:

    * ``rho_inf``: spectral radius at infinity, in [0, 1] (1.0 = no numerical
      dissipation, the implicit midpoint rule).
    * ``newton_iterations``: maximum Newton iterations per step (a fixed trip
      count: a bounded, checkpointed while loop that stops at convergence, so the step is
      reverse-mode differentiable).
    * ``full_newton``: True (default) re-evaluates the Jacobian at every
      iteration; False evaluates it once per step, at the predictor
      (simplified Newton: cheaper iterations, slower convergence; it can
      fail where the Jacobian changes much over a step).
    * ``jacobian_every``: with ``full_newton=False``, the LU factors of the Newton
      matrix are kept in the solver state and re-evaluated only every
      ``jacobian_every`` steps (1 = every step), or at once when an iteration with
      the kept factors fails to converge (the step is then redone with fresh
      ones).  For drives that move little about their state this removes the
      Jacobian (the dominant cost) from almost every step.
    * ``rtol``, ``atol``: convergence when the change of ``y_{n+1}`` by the last
      update, ``size`` (max norm over all components), times
      ``min(1, theta / (1 - theta))`` (Hairer & Wanner's estimate of the error
      left, theta = ratio of the last two update sizes, used when theta < 1/2)
      is at most ``atol + rtol * max|y_{n+1}|`` (atol in units of y).  A step
      whose Newton iteration has not converged within ``newton_iterations``,
      or has produced non-finite values, returns
      ``RESULTS.nonlinear_max_steps_reached`` / ``RESULTS.nonfinite``, so
      ``diffeqsolve`` stops (or raises, with ``throw=True``) instead of
      returning a wrong answer.

    With rho_inf = 1 the energy of a linear (or quadratic-energy) system is
    conserved to round-off; for a nonlinear one (e.g. Green-Lagrange axial
    strain) the energy error is O(h^2) but can grow when energetic modes are
    unresolved (h omega > 1): see tests/test_transient.py.
    """

    rho_inf: float = 1.0
    newton_iterations: int = eqx.field(default=8, static=True)
    full_newton: bool = eqx.field(default=True, static=True)
    jacobian_every: int = eqx.field(default=1, static=True)
    rtol: float = 1e-10
    atol: float = 1e-12

    term_structure: ClassVar = diffrax.ODETerm
    interpolation_cls: ClassVar[Callable[..., diffrax.LocalLinearInterpolation]] = (
        diffrax.LocalLinearInterpolation
    )

    def __check_init__(self):
        if not isinstance(self.rho_inf, jax.Array) and not 0.0 <= float(self.rho_inf) <= 1.0:
            raise ValueError(f"rho_inf must lie in [0, 1], got {self.rho_inf}")
        if int(self.newton_iterations) < 1:
            raise ValueError("newton_iterations must be >= 1")
        if int(self.jacobian_every) < 1:
            raise ValueError("jacobian_every must be >= 1")

    def order(self, terms):
        del terms
        return 2

    def error_order(self, terms):
        del terms
        return None

    # ------------------------------------------------------------------ helpers

    @staticmethod
    def _rate(terms, t0, t1, args):
        """f(t, y) per unit (signed) time in diffrax's internal time, as a function of t, y.

        diffrax wraps terms so that internal time always increases; going
        through ``vf_prod`` with the step's control keeps integrating backwards
        in time correct.
        """
        h = t1 - t0
        control = terms.contr(t0, t1)

        def rate(t, y):
            inc = terms.vf_prod(t, y, args, control)
            return jax.tree_util.tree_map(lambda x: x / h, inc)

        return rate

    # ------------------------------------------------------------------ interface

    def init(self, terms, t0, t1, y0, args):
        """Solver state: (ydot at t0 = f(t0, y0), Newton-matrix factors, their age in steps).

        The factors start as zeros aged ``jacobian_every`` (stale), so that the first step forms
        them, from the same predictor and step as they would be formed here: the same numbers,
        and the start's own program carries no Jacobian and LU (measured on a hybrid
        three-pulley drive: its XLA compilation fell from 9.8 s to 3.6 s)."""
        ydot0 = self._rate(terms, t0, t1, args)(t0, y0)
        a0 = ravel_pytree(ydot0)[0].astype(ravel_pytree(y0)[0].dtype)
        shapes = jax.eval_shape(self._factor_fn(terms, t0, t1, y0, ydot0, args)[1], a0)
        f0 = jax.tree_util.tree_map(lambda x: jnp.zeros(x.shape, x.dtype), shapes)
        return ydot0, f0, jnp.array(int(self.jacobian_every))

    def _predictor(self, ydot0_tree, y0):
        ydot0 = ravel_pytree(ydot0_tree)[0].astype(ravel_pytree(y0)[0].dtype)
        _, _, gamma = generalized_alpha_parameters(self.rho_inf)
        # JWH's "same y" predictor, y_{n+1} = y_n: robust for stiff (h omega >> 1) components,
        # whose rates ydot_n carry large, undamped (rho_inf = 1) oscillations.
        return (1.0 - 1.0 / gamma) * ydot0, ydot0

    def _factor_fn(self, terms, t0, t1, y0, ydot0_tree, args):
        """(residual(a), factor(a)) of the step t0 -> t1 from (y0, ydot0)."""
        rate = self._rate(terms, t0, t1, args)
        y0_flat, unravel = ravel_pytree(y0)
        ydot0 = ravel_pytree(ydot0_tree)[0].astype(y0_flat.dtype)
        h = t1 - t0
        alpha_m, alpha_f, gamma = generalized_alpha_parameters(self.rho_inf)
        t_f = t0 + alpha_f * h

        def residual(a):
            ydot_m = ydot0 + alpha_m * (a - ydot0)
            y1 = y0_flat + h * ydot0 + gamma * h * (a - ydot0)
            y_f = y0_flat + alpha_f * (y1 - y0_flat)
            f_val, _ = ravel_pytree(rate(t_f, unravel(y_f)))
            return ydot_m - f_val

        def factor(a):
            """LU factors of the row- and column-equilibrated Jacobian dR/da at a."""
            J = jax.jacfwd(residual)(a)
            # y often mixes scales (positions, and rates of stiff modes): equilibrate
            # so the LU solve keeps its accuracy (the raw J can have cond ~ 1e14).
            row = 1.0 / jnp.max(jnp.abs(J), axis=1)
            J = J * row[:, None]
            col = 1.0 / jnp.max(jnp.abs(J), axis=0)
            # keep the permutation, not LAPACK's pivots: turning pivots into a permutation is
            # a loop over the rows (jax.scipy.linalg.lu_solve did it at every Newton iteration, ~1 ms/step
            # for 200 unknowns on CPU)
            lu, _, perm = jax.lax.linalg.lu(J * col[None, :])
            if self.full_newton:
                return (lu, perm), row, col
            # kept factors serve many Newton iterations: store the inverse of the equilibrated
            # matrix, so that each iteration is one matrix-vector product instead of two
            # triangular solves (LAPACK calls whose fixed cost dominates for small drives).  Its
            # rounding only changes the contraction of the (simplified) Newton iteration, not the
            # solution, which is the residual's zero.
            eye = jnp.eye(J.shape[0], dtype=J.dtype)
            return _lu_solve(lu, perm, eye), row, col

        return residual, factor

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        """One generalized-alpha step t0 -> t1; returns (y1, None, dense_info, state1, result)."""
        rate = self._rate(terms, t0, t1, args)
        ydot0_tree, factors_kept, age = solver_state
        if made_jump is True:
            ydot0_tree = rate(t0, y0)
        elif made_jump is not False:
            ydot0_tree = jax.lax.cond(made_jump, lambda: rate(t0, y0), lambda: ydot0_tree)

        y0_flat, unravel = ravel_pytree(y0)
        h = t1 - t0
        _, _, gamma = generalized_alpha_parameters(self.rho_inf)
        residual, factor = self._factor_fn(terms, t0, t1, y0, ydot0_tree, args)
        a0, ydot0 = self._predictor(ydot0_tree, y0)

        def y_next(a):
            return y0_flat + h * ydot0 + gamma * h * (a - ydot0)

        def solve(factors, r):
            lu_or_inverse, row, col = factors
            if self.full_newton:
                return col * _lu_solve(*lu_or_inverse, (row * r)[:, None])[:, 0]
            return col * (lu_or_inverse @ (row * r))

        def newton_update(carry):
            a, _, _, factors, prev = carry
            if self.full_newton:
                factors = factor(a)
            delta = solve(factors, residual(a))
            a_new = a - delta
            size = gamma * h * jnp.max(jnp.abs(delta))  # change of y_{n+1} by this update
            # Hairer & Wanner's estimate of the remaining error, theta/(1 - theta) * size
            # with the observed contraction theta, used only where it is below size.
            theta = size / prev
            # (prev = inf at the first iteration: no estimate, eta = 1)
            eta = jnp.where(jnp.isfinite(prev) & (theta < 0.5), theta / (1.0 - theta), 1.0)
            tol = self.atol + self.rtol * jnp.max(jnp.abs(y_next(a_new)))
            finite = jnp.all(jnp.isfinite(a_new))
            return a_new, finite & (eta * size <= tol), finite, factors, size

        def go_on(carry):
            converged, finite = carry[1], carry[2]
            return ~converged & finite

        def newton(factors):
            init = (a0, jnp.array(False), jnp.array(True), factors, jnp.array(jnp.inf, dtype=a0.dtype))
            # a bounded while loop: stops at convergence (or failure), at most newton_iterations
            # trips, and stays reverse-mode differentiable (checkpointed); a fori_loop over a
            # cond did the same work about 4x slower on CPU
            a, converged, finite, _, _ = eqxi.while_loop(
                go_on, newton_update, init, max_steps=int(self.newton_iterations), kind="checkpointed"
            )
            return a, converged, finite

        if self.full_newton:
            a, converged, finite = newton(factors_kept)
            new_state_factors, new_age = factors_kept, age
        else:
            every = int(self.jacobian_every)
            if every == 1:
                fresh = factor(a0)
                a, converged, finite = newton(fresh)
                new_state_factors, new_age = fresh, jnp.array(0)
            else:
                stale = (age >= every) | jnp.asarray(made_jump)

                def attempt(carry):
                    """One Newton solve of the step: with the kept factors at the first attempt
                    (unless stale), with fresh ones at the second."""
                    k, _, _, _, kept, _ = carry
                    fresh = stale | (k > 0)
                    factors = jax.lax.cond(fresh, lambda: factor(a0), lambda: kept)
                    return (k + 1, *newton(factors), factors, fresh)

                def again(carry):
                    k, _, converged, _, _, fresh = carry
                    return (k == 0) | (~converged & ~fresh)

                # at most two attempts in one loop: the program holds one copy of the Jacobian, its
                # LU and the Newton iteration (a cond between a kept-factor attempt and a redo held
                # two: a hybrid three-pulley drive's chunk compiled in 15.7 s instead of 20.4 s, same numbers)
                start = (jnp.array(0), a0, jnp.array(False), jnp.array(True), factors_kept, jnp.array(False))
                _, a, converged, finite, new_state_factors, fresh = eqxi.while_loop(
                    again, attempt, start, max_steps=2, kind="checkpointed"
                )
                new_age = jnp.where(fresh, 1, age + 1)

        y1_flat = y_next(a)
        y1 = unravel(y1_flat)
        ydot1 = unravel(a)
        result = diffrax.RESULTS.where(
            converged,
            diffrax.RESULTS.successful,
            diffrax.RESULTS.where(finite, diffrax.RESULTS.nonlinear_max_steps_reached, diffrax.RESULTS.nonfinite),
        )
        dense_info = dict(y0=y0, y1=y1)
        return y1, None, dense_info, (ydot1, new_state_factors, new_age), result

    def func(self, terms, t0, y0, args):
        """The vector field f(t0, y0)."""
        return terms.vf(t0, y0, args)
