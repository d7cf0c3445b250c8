"""The periodic steady state by shooting (pure JAX: jit, vmap, grad): Newton's method on the
one-cycle map of the drive's equations, y(0) = Phi(y(0)), instead of a transient that waits for
the start-up to die out.

Each Newton iteration integrates one excitation cycle together with the variational equations
Y' = (df/dy) Y, Y(0) = I (the state Jacobian applied to the N columns of Y by a vmapped
``jax.linearize`` of the vector field; a step cost about 2.5 plain ones on the eight-pulley
drive with the friction tensioner, measured once: the vector field is overhead-bound on a CPU).
The step control holds Y 1000x looser than the state (:func:`error_norm`): on the state alone a
drive at rest takes steps its linearisation cannot, and P comes out wrong; held as tight as the
state, 100 speeds of that drive took 77 s instead of 60 s (measured once).  The cycle's end gives
the monodromy matrix P = Y(T) and the update y <- y - (P - I)^-1 (Phi(y) - y), damped to at
most the cycle's own range of motion (:data:`MAX_STEP`).  It starts on the linearised drive's
periodic response (:mod:`beltjax.orders.linear_start`), and on the eight-pulley drives it
converges in 2-5 iterations (8-10 where dry friction holds the arm), where a settling transient needs about a second of simulated time
(13 cycles at 800 rpm, 100 at 6000): ``benchmarks/bench_orders.py``.

A fixed point is only the response an engine shows when it attracts: the largest Floquet
multiplier (the spectral radius of P, estimated as ||P^m||^(1/m), m = 2^20, by repeated
squaring, as ``jnp.linalg.eigvals`` has no accelerator kernel) must be below 1 (without
gradients, below 1 + :data:`NEUTRAL`: a neutral cycle, such as a friction-held arm's, is a
steady state too).  A case that does
not converge in :data:`MAX_ITERATIONS`, gives a non-finite state or an unstable cycle, or whose
iterate's cycle takes more than :data:`BUDGET_FACTOR` times the steps of its first (the iterate
has left the cycle; :class:`StepBudget`) is left to the settling transient
(:func:`beltjax.orders.run.response_over_speed` re-runs it that way).  Not for states that drift
(``belt_slip``'s creeping pulleys and slip states: no fixed point): those settle.

Gradients: the Newton loop runs on stopped gradients; the implicit function theorem enters
through one more Newton step, y* = y - (P - I)^-1 (Phi(y; p) - y), with the map Phi integrated
differentiably and P held: its value is a further correction (the residual squared), its
derivative in any parameter p is -(P - I)^-1 dPhi/dp, the fixed point's.

Without gradients (``gradients=False``: a response over speed, a sweep) that cycle is not run and
the last Newton step is taken where it is small (reach at most :data:`PREDICT_REACH`: like the
gradient path's implicit-function step, it is not confirmed by a cycle of its own; the recorded
cycle's change is the case's ``settling``), and the loop also stops on Newton's prediction: once
the iterate is in the quadratic range (residual at most :data:`PREDICT_RESIDUAL`) a step of reach r
leaves a residual of about C r^2 (C = 0.14-0.56 on the eight-pulley drive with the friction
tensioner, 600-6000 rpm), so a step of reach at most :data:`PREDICT_REACH` is taken without the
cycle that would confirm it (a cycle with the variational equations, about 2.5 plain ones). The
caller's recorded cycle confirms that state instead: its change over the cycle, divided by 1 - mu
(mu the largest Floquet multiplier: a change d puts the state about d / (1 - mu) from the cycle),
must be within :data:`PREDICT_CHECK` (a neutral cycle's, mu's estimate at least 1, within
:data:`TOLERANCE`: it drifts along its family at no error; :func:`beltjax.orders.steady.steady_case`,
else the case settles). On the eight-pulley drives 100 speeds took 25 % less (benchmarks/README §5g). The
values agree with the converged loop's to the tolerance; their gradients would not (P is the last
iterate's), hence the flag, and differentiating a ``gradients=False`` orbit raises
(:func:`refuse_tangents`).
"""

from __future__ import annotations

import diffrax
import jax
import jax.numpy as jnp
import optimistix as optx

#: the variational equations' error counts this much against the state's in the step control
Y_WEIGHT = 1e-3


def error_norm(err) -> jax.Array:
    """The step control's norm of the scaled error (state, Y): the larger of the state's rms and
    :data:`Y_WEIGHT` times Y's (-)."""
    return jnp.maximum(optx.rms_norm(err[0]), Y_WEIGHT * optx.rms_norm(err[1]))

#: most Newton iterations (each one cycle with the variational equations).  12, not 8: an arm
#: that dry friction holds nearly all cycle walks to its place by tiny slips at the band's edge
#: (Floquet multipliers 0.999-0.9997 on the eight-pulley drive at 3800-4500 rpm), where Newton
#: took 8-10 iterations; with 8 those speeds fell to the settling transient, which needed 4 s
#: (100 speeds: 63.3 s against 34.8 s; benchmarks/README.md section 5g)
MAX_ITERATIONS = 12
#: convergence: the state's change over one cycle against its range over the cycle (positions and
#: speeds apart, as the settling residual :func:`beltjax.orders.steady._settling`)
TOLERANCE = 1e-6
#: motion below this range (rad, m or their rates) counts as none in the convergence test
RANGE_FLOOR = 1e-9
#: ... and so does motion within this many of the integration's tolerances (atol + rtol |y|)
NOISE_RANGE = 1e3
#: a Newton iterate whose change over the cycle is within this many tolerances of every
#: coordinate has converged as far as the integration allows (a drive that hardly moves)
NOISE_STOP = 10.0
#: largest Newton step against the cycle's range of motion (positions and speeds apart, -)
MAX_STEP = 1.0
#: most steps of one cycle's integration (a cycle of the eight-pulley drive with a dry-friction
#: tensioner takes 700-7,000; more means the iterate has left the drive's cycle: the case settles)
MAX_CYCLE_STEPS = 50_000
#: a Newton iterate's cycle may take at most this many times the steps of the first cycle (from
#: the linearised start); more and the iterate has left the region where Newton converges: the
#: case settles.  On the eight-pulley drive with the friction tensioner (1000 speeds, 600-6000
#: rpm) a converging iterate's cycle took at most 1.48x the first's; in the slack-span band the
#: diverging ones grew to 3-7x and twice to the 50,000-step cap, which a lock-step batch of 1000
#: speeds on a GPU waited for (benchmarks/bench_lockstep.py, benchmarks/README.md section 5g)
BUDGET_FACTOR = 4
#: the part of a cycle that a case whose Newton loop has ended integrates while a vmapped batch
#: runs on (its result is discarded)
IDLE_FRACTION = 1e-9
#: squarings of P in the spectral-radius estimate (P^(2^SQUARINGS))
SQUARINGS = 20
#: without gradients, a cycle whose largest Floquet multiplier estimate is below 1 + NEUTRAL (-)
#: counts as a steady state: a neutral direction, such as an arm that dry friction holds wherever
#: it stopped (the eight-pulley drive with the friction tensioner at 4745-4855 rpm: 1 + 3e-7 to
#: 1 + 4e-7 after 1-2 iterations, which then settled for 1 s each), reads above 1 by the estimate's
#: bias, up to ln(cond of P's eigenvectors) / 2^SQUARINGS (8.8e-6 for a condition of 1e4); a
#: perturbation that grows by 1e-5 a cycle takes 100,000 cycles to grow e-fold.  With gradients
#: the test stays strict (< 1): the derivative of a neutral family's member is not defined.
NEUTRAL = 1e-5
#: without gradients: a Newton step of at most this reach (-) from an iterate whose residual is at
#: most :data:`PREDICT_RESIDUAL` (-) ends the loop (module docstring; C r^2 <= 0.56e-6 seen)
PREDICT_REACH = 1e-3
PREDICT_RESIDUAL = 1e-2
#: ... and the recorded cycle from it must change by at most this (-) times 1 - (largest Floquet
#: multiplier): the state within about this of the cycle, 100x :data:`TOLERANCE`
PREDICT_CHECK = 1e-4


def prediction_confirmed(change, multiplier, predicted):
    """Whether a cycle's state is its periodic state (bool array): where the Newton loop stopped on
    its prediction (``predicted`` > 0.5), the recorded cycle's ``change`` (-,
    :func:`change_over_cycle`) must be within :data:`PREDICT_CHECK` times 1 - ``multiplier`` (-;
    a change d puts the state about d / (1 - mu) from the cycle), or, for a neutral cycle (the
    multiplier's estimate, never below the true value, at least 1: a friction-held arm, which
    drifts along its family at no error), within the loop's own :data:`TOLERANCE`."""
    allowed = jnp.where(multiplier >= 1.0, TOLERANCE, PREDICT_CHECK * (1.0 - multiplier))
    return (predicted < 0.5) | (change <= allowed)


def change_over_cycle(y_start, y_end, samples, n: int, rtol: float, atol: float):
    """The state's change over one cycle, y_end - y_start (2n,), against its range over the cycle's
    ``samples`` (K, 2n), for the n positions and the n speeds apart; the larger of the two (-).  A
    range within :data:`NOISE_RANGE` of the integration's tolerances (rtol, atol) counts as that
    much: the change of a drive that hardly moves is its integration error, not a start-up."""
    return relative_change(y_end - y_start, samples, n, rtol, atol, RANGE_FLOOR)


def relative_change(dy, samples, n: int, rtol: float = 0.0, atol: float = 0.0, floor: float = 1e-300):
    """max |dy| ((2n,) or (K, 2n)) against the largest range of ``samples`` (K, 2n) over K, for the
    n positions and the n speeds apart; the larger of the two (-).  A range below ``floor`` or
    within :data:`NOISE_RANGE` of the integration's tolerances (rtol, atol) counts as that much.
    The one measure of the shooting's convergence and of the settling residual."""
    def part(sl):
        x = samples[:, sl]
        span = jnp.max(x.max(axis=0) - x.min(axis=0))
        least = jnp.maximum(floor, NOISE_RANGE * (atol + rtol * jnp.max(jnp.abs(x))))
        return jnp.max(jnp.abs(dy[..., sl])) / jnp.maximum(span, least)

    return jnp.maximum(part(slice(0, n)), part(slice(n, 2 * n)))


class StepBudget(diffrax.AbstractStepSizeController):
    """``controller`` that ends the solve (diffrax's ``max_steps_reached``) once ``budget`` steps,
    accepted or rejected, have been tried: a step cap that may be a traced value (diffrax's
    ``max_steps`` is static), per case in a vmapped batch."""

    controller: diffrax.AbstractStepSizeController
    budget: jax.Array

    def wrap(self, direction):
        return StepBudget(self.controller.wrap(direction), self.budget)

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        tnext, state = self.controller.init(terms, t0, t1, y0, dt0, args, func, error_order)
        return tnext, (state, jnp.asarray(0))

    def adapt_step_size(self, t0, t1, y0, y1_candidate, args, y_error, error_order, controller_state):
        state, tried = controller_state
        keep, t_next, t_after, jump, state, result = self.controller.adapt_step_size(
            t0, t1, y0, y1_candidate, args, y_error, error_order, state)
        tried = tried + 1
        over = tried >= self.budget
        result = diffrax.RESULTS.where(over & (result == diffrax.RESULTS.successful),
                                       diffrax.RESULTS.max_steps_reached, result)
        return keep, t_next, t_after, jump, (state, tried), result


def spectral_radius(P):
    """max |eigenvalue| of the square matrix P (-), as ||P^(2^k)||^(1/2^k) with k = :data:`SQUARINGS`
    (rescaled at each squaring: no overflow); above the true value by at most a factor
    (cond of P's eigenvectors)^(2^-20)."""
    def sq(c, _):
        A, log_n = c
        A = A @ A
        s = jnp.maximum(jnp.linalg.norm(A), 1e-300)
        return (A / s, 2.0 * log_n + jnp.log(s)), None

    s0 = jnp.maximum(jnp.linalg.norm(P), 1e-300)
    (_, log_n), _ = jax.lax.scan(sq, (P / s0, jnp.log(s0)), None, length=SQUARINGS)
    return jnp.exp(log_n / 2.0**SQUARINGS)


def held(tree):
    """``tree`` with the gradients of its array leaves stopped (what the Newton loop closes over)."""
    return jax.tree_util.tree_map(lambda x: jax.lax.stop_gradient(x) if isinstance(x, jax.Array) else x, tree)


@jax.custom_jvp
def _no_tangent(x):
    return x


@_no_tangent.defjvp
def _no_tangent_jvp(primals, tangents):
    raise ValueError("gradients: this periodic orbit was found with gradients=False (orders.Settings), which takes "
                     "Newton's last step without the implicit-function cycle; differentiate with gradients=True")


def refuse_tangents(tree):
    """``tree`` unchanged; differentiating through any of its array leaves raises (a shooting with
    ``gradients=False``, whose derivative would miss the fixed point's)."""
    return jax.tree_util.tree_map(lambda x: _no_tangent(x) if isinstance(x, jax.Array) else x, tree)


def periodic_orbit(f, f_held, y0, period, ts, solver, controller, max_steps: int, n: int, gradients: bool = True):
    """The state y(0) of the periodic solution of y' = f(t, y, None) with period ``period`` (s),
    by Newton's method from ``y0`` (the state's units); ``ts`` (K,) the cycle's sample times (s,
    for the convergence test's ranges), ``solver``, ``controller`` (diffrax; the controller's step
    control is applied to the state alone), ``max_steps`` per cycle (at most
    :data:`MAX_CYCLE_STEPS`), n the number of coordinates (the state's first 2n entries are
    positions and speeds); ``f_held``: the same vector field
    with its parameters' gradients stopped (:func:`held`), which the Newton loop integrates.

    Returns (y* (N,), info) with info: ``iterations``, ``residual`` (:func:`change_over_cycle` of
    the last iterate), ``multiplier`` (largest Floquet multiplier, -), ``steps`` (all cycles),
    ``cycle_steps`` (:data:`MAX_ITERATIONS`,) each Newton cycle's steps (0 after the last),
    ``ok`` (1.0 / 0.0: converged, to :data:`TOLERANCE` or to the integration's own error
    (:data:`NOISE_STOP`), finite and attracting, or without gradients neutral: multiplier below
    1 + :data:`NEUTRAL`), ``predicted`` (1.0 where the loop stopped on
    Newton's prediction: the caller checks the next cycle against :data:`PREDICT_CHECK`) as floats.
    Differentiable in the parameters ``f`` closes over if ``gradients`` (static; module docstring)."""
    N = y0.shape[0]
    max_steps = min(max_steps, MAX_CYCLE_STEPS)
    T, t_samples = jax.lax.stop_gradient(period), jax.lax.stop_gradient(ts)
    eye = jnp.eye(N, dtype=y0.dtype)

    def variational(t, s, args):
        y, Y = s
        fy, lin = jax.linearize(lambda z: f_held(t, z, None), y)
        return fy, jax.vmap(lin, in_axes=1, out_axes=1)(Y)

    rtol, atol = controller.rtol, controller.atol
    ctrl = diffrax.PIDController(rtol=controller.rtol, atol=controller.atol,
                                 dtmax=None if controller.dtmax is None else jax.lax.stop_gradient(controller.dtmax),
                                 norm=error_norm)

    def cycle(y, budget, active):
        # a case whose loop has ended (vmapped: the body runs for the whole batch, its result
        # discarded) integrates a vanishing interval, so that a lock-step batch's iteration lasts
        # as long as its slowest *running* case (bench_lockstep.py: 8,274 -> 6,492 cycle steps)
        s = jnp.where(active, 1.0, IDLE_FRACTION)
        sol = diffrax.diffeqsolve(diffrax.ODETerm(variational), solver, t0=0.0, t1=T * s, dt0=T * s / 64,
                                  y0=(y, eye), saveat=diffrax.SaveAt(ts=t_samples * s, t1=True, fn=lambda t, s, a: s),
                                  stepsize_controller=StepBudget(ctrl, budget), max_steps=max_steps, throw=False)
        ys, Ys = sol.ys
        return ys[:-1], ys[-1], Ys[-1], sol.stats["num_steps"], sol.result == diffrax.RESULTS.successful

    def cond(c):
        return (c["k"] < MAX_ITERATIONS) & ~c["done"] & c["finite"]

    def body(c):
        budget = jnp.where(c["k"] == 0, max_steps, BUDGET_FACTOR * c["cycle_steps"][0])  # (BUDGET_FACTOR)
        samples, yT, P, steps, good = cycle(c["y"], budget, cond(c))
        r = yT - c["y"]
        res = change_over_cycle(c["y"][: 2 * n], yT[: 2 * n], samples[:, : 2 * n], n, rtol, atol)
        at_noise = jnp.all(jnp.abs(r) <= NOISE_STOP * (atol + rtol * jnp.abs(yT)))
        step = jnp.linalg.solve(P - eye, r)
        # damped: a step at most the cycle's own range of motion (far from the cycle, near a
        # resonance, a full step can throw the state where the cycle takes max_steps)
        reach = relative_change(step[: 2 * n], samples[:, : 2 * n], n, rtol, atol, RANGE_FLOOR)
        step = step / jnp.maximum(1.0, reach / MAX_STEP)
        finite = good & jnp.all(jnp.isfinite(step)) & jnp.isfinite(res)
        done = (res <= TOLERANCE) | at_noise
        predicted = jnp.asarray(False)
        if gradients:  # the implicit function's cycle below starts where the residual was measured
            y = jnp.where(done | ~finite, c["y"], c["y"] - step)
        else:  # the step predicted to converge, which the recorded cycle confirms (module docstring), and
            # the last step from a converged iterate where small, as the implicit function's step of the
            # gradient path (an ill-conditioned P - I may make it large and of no use)
            predicted = ~done & (res <= PREDICT_RESIDUAL) & (reach <= PREDICT_REACH)
            y = jnp.where(finite & (~done | (reach <= PREDICT_REACH)), c["y"] - step, c["y"])
            done = done | predicted
        return dict(y=y, k=c["k"] + 1, residual=jnp.where(finite, res, jnp.inf), P=jnp.where(finite, P, c["P"]),
                    steps=c["steps"] + steps, cycle_steps=c["cycle_steps"].at[c["k"]].set(steps), finite=finite, done=done & finite,
                    predicted=predicted & finite)

    init = dict(y=jax.lax.stop_gradient(y0), k=jnp.asarray(0), residual=jnp.asarray(jnp.inf, y0.dtype), P=eye,
                steps=jnp.asarray(0), cycle_steps=jnp.zeros(MAX_ITERATIONS, int),
                finite=jnp.asarray(True), done=jnp.asarray(False), predicted=jnp.asarray(False))
    c = jax.lax.while_loop(cond, body, init)
    mult = spectral_radius(c["P"])
    if gradients:  # the implicit function theorem's step (module docstring): Phi integrated with gradients, P held
        plain = diffrax.diffeqsolve(diffrax.ODETerm(f), solver, t0=0.0, t1=period, dt0=period / 64, y0=c["y"],
                                    stepsize_controller=controller, max_steps=max_steps, throw=False)
        rhs = plain.ys[-1] - c["y"]
        usable = c["done"] & jnp.all(jnp.isfinite(rhs))  # else no step (and no NaN in the gradient)
        correction = jnp.linalg.solve(jnp.where(usable, c["P"] - eye, eye), jnp.where(usable, rhs, 0.0))
        y_star, steps = c["y"] - correction, c["steps"] + plain.stats["num_steps"]
    else:  # the loop's last iterate (its last step taken)
        y_star, steps, usable = c["y"], c["steps"], c["done"]
    ok = usable & (mult < (1.0 if gradients else 1.0 + NEUTRAL)) & jnp.all(jnp.isfinite(y_star))
    info = dict(iterations=c["k"].astype(y0.dtype), residual=c["residual"], multiplier=mult, steps=steps.astype(y0.dtype),
                ok=ok.astype(y0.dtype), predicted=c["predicted"].astype(y0.dtype),
                cycle_steps=c["cycle_steps"].astype(y0.dtype))
    return y_star, info
