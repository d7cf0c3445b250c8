"""A start for the settling transient: the periodic response of the equations linearised about
the operating point (pure JAX: jit, vmap, grad).

Settling from the operating point (the mean state, at rest in the rotating frame) excites every
mode at once, and the slowest-decaying one sets how long the transient must run: the alternator
decoupler's rotor mode (12.6 Hz, damping ratio 0.08 on the eight-pulley drive) had not died out
after 1 s at any of 100 speeds, so each ran again 4x longer.  Started instead on the linearised
drive's periodic response, the transient begins close to the steady state: only the nonlinear
remainder has to decay.  The settling check (:func:`beltjax.orders.steady._settling`) decides
as before; this start only changes how soon it passes.

The linearisation: y' = f(t, y) about the operating point y0 is y' = A (y - y0) + f(t, y0), with
A the state Jacobian averaged over one excitation cycle (the speed fluctuation makes it vary a
little) and b(t) = f(t, y0) sampled at K points of the cycle.  Each harmonic k >= 1 of b (its
discrete Fourier coefficient) gives the periodic response's harmonic (i k w I - A)^-1 B_k; the
mean (k = 0) is left at y0, which is the mean-load equilibrium (with ``belt_slip`` a creeping
pulley's angle drifts: its mean rate is in y0 already).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def linear_periodic_start(f, y0, period, samples: int, jacobian_samples: int = 8, harmonics: int | None = None):
    """The state at t = 0 (y0's units) of the periodic response of ``f`` (f(t, y, args), the
    transient's vector field) linearised about ``y0`` (the operating point), for an excitation
    that repeats every ``period`` (s); b(t) = f(t, y0) is sampled at ``samples`` points of the
    cycle, the Jacobian averaged over ``jacobian_samples`` of them; the response to the first
    ``harmonics`` harmonics of the cycle (default all that the samples resolve).  Falls back to
    ``y0`` where the result is not finite (a singular linearisation)."""
    ts = period * jnp.arange(samples) / samples
    b = jax.vmap(lambda t: f(t, y0, None))(ts)  # (K, N)
    tj = period * jnp.arange(jacobian_samples) / jacobian_samples
    A = jnp.mean(jax.vmap(lambda t: jax.jacfwd(lambda y: f(t, y, None))(y0))(tj), axis=0)
    top = (samples + 1) // 2 if harmonics is None else min(harmonics + 1, (samples + 1) // 2)
    B = jnp.fft.rfft(b, axis=0)[1:top] / samples  # (H, N): b(t) ~ sum_k 2 Re(B_k e^{i k w t}), no Nyquist term
    w = 2.0 * jnp.pi / period * jnp.arange(1, B.shape[0] + 1)
    eye = jnp.eye(y0.shape[0])
    Y = jnp.linalg.solve(1j * w[:, None, None] * eye - A, B[..., None])[..., 0]  # (H, N)
    y = y0 + 2.0 * jnp.sum(Y.real, axis=0)
    return jnp.where(jnp.all(jnp.isfinite(y)), y, y0)
