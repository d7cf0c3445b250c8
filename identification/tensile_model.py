"""The tensile model and its optimiser: the complex modulus G(f) = a1 f^b1 + a2 f^b2 (eq. 6.1, f in Hz,
G in N), its weighted residuals, the batched L-BFGS + Levenberg-Marquardt fit from several starts,
and the starting values (log-log lines, a1 and a2 by variable projection)."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import optax

import beltjax  # noqa: F401  (float64)
from identification import least_squares


#: optimiser settings: starts minimised together, L-BFGS iterations, Levenberg-Marquardt iterations
N_STARTS = 8


LBFGS_STEPS = 150


LM_STEPS = 40
#: the Levenberg-Marquardt polish stops when the Cauchy test holds at these tolerances
LM_RTOL, LM_ATOL = 1e-10, 1e-13


def _residual_fn(theta, a):
    """_residuals(theta, f, G, W) with a = (f, G, W), for the least-squares layer."""
    return _residuals(theta, *a)


#: frequency-grid length of one evaluation call (bands and tables are padded to it)
_EVAL_N = 256


def power_sum(theta: jax.Array, f: jax.Array) -> jax.Array:
    """G(f) = a1 f^b1 + a2 f^b2 (complex, N/mm) for f in Hz; theta = (Re a1, Im a1, ..., Im b2)."""
    a1, a2 = theta[0] + 1j * theta[1], theta[2] + 1j * theta[3]
    b1, b2 = theta[4] + 1j * theta[5], theta[6] + 1j * theta[7]
    lnf = jnp.log(f)
    return a1 * jnp.exp(b1 * lnf) + a2 * jnp.exp(b2 * lnf)


def _residuals(theta, f, G, W):
    """Whitened residuals W_k (G(f_k) - G_k), flattened (2 per record; padded records give 0)."""
    d = power_sum(theta, f) - (G[:, 0] + 1j * G[:, 1])
    dd = jnp.stack([d.real, d.imag], axis=-1)
    return jnp.einsum("kij,kj->ki", W, dd).reshape(-1)


def _chi2(theta, f, G, W):
    r = _residuals(theta, f, G, W)
    v = jnp.sum(r**2)
    return jnp.where(jnp.isfinite(v), v, jnp.inf)


def _fit_one(theta0, f, G, W):
    """L-BFGS (optax) in Jacobi-scaled coordinates, then Levenberg-Marquardt (the fits'
    least-squares layer, same scaling), from one start."""
    J0 = jax.jacfwd(_residuals)(theta0, f, G, W)
    D = least_squares.column_scale(J0)

    def loss(u):
        r = _residuals(theta0 + u / D, f, G, W)
        return 0.5 * jnp.sum(r**2)

    opt = optax.lbfgs()
    value_and_grad = optax.value_and_grad_from_state(loss)

    def lbfgs_step(carry, _):
        u, state = carry
        v, g = value_and_grad(u, state=state)
        upd, state_new = opt.update(g, state, u, value=v, grad=g, value_fn=loss)
        u_new = optax.apply_updates(u, upd)
        ok = jnp.all(jnp.isfinite(u_new)) & jnp.isfinite(v)
        u_new = jnp.where(ok, u_new, u)
        state_new = jax.tree_util.tree_map(lambda a, b: jnp.where(ok, a, b), state_new, state)
        return (u_new, state_new), v

    u0 = jnp.zeros_like(theta0)
    (u, _), hist_lbfgs = jax.lax.scan(lbfgs_step, (u0, opt.init(u0)), None, length=LBFGS_STEPS)
    theta = theta0 + u / D
    theta = jnp.where(jnp.isfinite(_chi2(theta, f, G, W)), theta, theta0)

    sol = least_squares.solve(_residual_fn, theta, (f, G, W), D, LM_STEPS, history=LM_STEPS, rtol=LM_RTOL,
                              atol=LM_ATOL)
    ok = jnp.isfinite(_chi2(sol.x, f, G, W))
    theta = jnp.where(ok, sol.x, theta)
    hist_lm = sol.loss[1:]  # the first entry is the start, the last L-BFGS loss
    return theta, hist_lbfgs, hist_lm


@jax.jit
def _fit_batch(theta0s, f, G, W):
    """All starts at once: fitted thetas (S, 8), L-BFGS and LM loss histories (S, steps)."""
    return jax.vmap(_fit_one, in_axes=(0, None, None, None))(theta0s, f, G, W)


@jax.jit
def _jacobian(theta, f, G, W):
    """Whitened residuals and their Jacobian d r / d theta at theta."""
    return _residuals(theta, f, G, W), jax.jacfwd(_residuals)(theta, f, G, W)


@jax.jit
def _evaluate(theta, f):
    """G(f) as (n, 2) (Re, Im; N/mm) and its Jacobian (n, 2, 8) with respect to theta."""

    def g(th, fk):
        z = power_sum(th, fk)
        return jnp.stack([z.real, z.imag])

    return jax.vmap(g, in_axes=(None, 0))(theta, f), jax.vmap(jax.jacfwd(g), in_axes=(None, 0))(theta, f)


def evaluate(theta: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Model G(f) (complex, N/mm) and dG/dtheta (complex, n x 8) at frequencies f (Hz)."""
    f = np.atleast_1d(np.asarray(f, dtype=np.float64))
    Gs, Js = [], []
    for s in range(0, len(f), _EVAL_N):
        chunk = f[s:s + _EVAL_N]
        pad = np.ones(_EVAL_N)
        pad[:len(chunk)] = chunk
        Gp, Jp = _evaluate(jnp.asarray(theta), jnp.asarray(pad))
        Gs.append(np.asarray(Gp)[:len(chunk)])
        Js.append(np.asarray(Jp)[:len(chunk)])
    Gr, Jr = np.concatenate(Gs), np.concatenate(Js)
    return Gr[:, 0] + 1j * Gr[:, 1], Jr[:, 0, :] + 1j * Jr[:, 1, :]


def _weighted_line(x: np.ndarray, y: np.ndarray, w: np.ndarray) -> tuple[float, float]:
    """Weighted least-squares line y = c0 + c1 x (minimum-norm when x is constant)."""
    A = np.column_stack([np.ones_like(x), x]) * w[:, None]
    (c0, c1), *_ = np.linalg.lstsq(A, y * w, rcond=None)
    return float(c0), float(c1)


def _log_fit(f: np.ndarray, G: np.ndarray, sigma: np.ndarray) -> tuple[complex, complex]:
    """(a, b) of a weighted fit ln G = ln a + b ln f (sigma of ln G ~ sigma / |G|)."""
    keep = np.isfinite(G) & (np.abs(G) > 0)
    if np.count_nonzero(keep) < 2:
        return complex(np.mean(G[np.isfinite(G)]) if np.any(np.isfinite(G)) else 1.0), 0j
    order = np.argsort(f[keep])
    lnf, z, s = np.log(f[keep][order]), G[keep][order], sigma[keep][order]
    w = np.abs(z) / s
    w = w / np.max(w)
    p0, p1 = _weighted_line(lnf, np.log(np.abs(z)), w)
    q0, q1 = _weighted_line(lnf, np.unwrap(np.angle(z)), w)
    return complex(np.exp(p0) * np.cos(q0), np.exp(p0) * np.sin(q0)), complex(p1, q1)


def _project(f, G, sigma, b1: complex, b2: complex) -> tuple[np.ndarray, float]:
    """Variable projection: a1, a2 solved linearly for fixed b1, b2; returns theta and chi^2."""
    A = np.column_stack([f**b1, f**b2]) / sigma[:, None]
    a, *_ = np.linalg.lstsq(A, G / sigma, rcond=None)
    chi2 = float(np.sum(np.abs(A @ a - G / sigma) ** 2))
    theta = np.array([a[0].real, a[0].imag, a[1].real, a[1].imag, b1.real, b1.imag, b2.real, b2.imag])
    return theta, chi2 if np.all(np.isfinite(theta)) else math.inf


def initial_guesses(f: np.ndarray, G: np.ndarray, sigma: np.ndarray, n: int = N_STARTS) -> np.ndarray:
    """``n`` deterministic starting thetas, best first (dominant term from a log-log fit)."""
    a1, b1 = _log_fit(f, G, sigma)
    rest = G - a1 * f**b1
    _, b2_rest = _log_fit(f, rest, sigma)
    cands = [b2_rest] + [complex(re, im) for re in (-1.0, -0.5, -0.2, 0.2, 0.5, 1.0) for im in (-0.5, 0.0, 0.5)]
    scored = []
    for b2 in cands:
        if abs(b2 - b1) < 1e-3:
            continue
        th, chi2 = _project(f, G, sigma, b1, b2)
        if math.isfinite(chi2):
            scored.append((chi2, th))
    scored.sort(key=lambda s: s[0])
    starts = [th for _, th in scored[:n]]
    while len(starts) < n:
        starts.append(starts[-1] if starts else np.array([abs(a1), 0, 0, 0, b1.real, b1.imag, -0.5, 0]))
    return np.stack(starts)
