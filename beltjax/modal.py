"""Eigen-analysis of linearised mechanical systems M x'' + G x' + K x = 0.

Generic over the system: the span analysis and later the drive models hand
their reduced matrices (from autodiff) to these functions.

* ``symmetric_modes`` (G = 0): Cholesky of M and ``eigh``; differentiable.
* ``gyroscopic_modes`` (G skew, from belt transport): the first-order
  companion form and a general eigen-solver.

A system is stable when no eigenvalue has a positive real part beyond the
round-off floor; unstable eigenvalues are returned, frequencies are not
invented for an unstable system.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

#: Relative size (to the largest |eigenvalue|) above which a positive real
#: part (or a negative omega^2) counts as an instability and not round-off.
STABILITY_RTOL = 1e-7


def symmetric_modes(M, K):
    """Undamped modes of (M, K), both symmetric, M positive definite.

    Returns ``(omega2, shapes)``: squared circular frequencies (rad^2/s^2,
    ascending; negative values mean divergence) and M-orthonormal mode shapes as
    columns.
    """
    Lc = jnp.linalg.cholesky(M)
    Linv_K = jax.scipy.linalg.solve_triangular(Lc, K, lower=True)
    A = jax.scipy.linalg.solve_triangular(Lc, Linv_K.T, lower=True)
    A = 0.5 * (A + A.T)
    omega2, V = jnp.linalg.eigh(A)
    shapes = jax.scipy.linalg.solve_triangular(Lc.T, V, lower=False)
    return omega2, shapes


def gyroscopic_eigen(M, G, K):
    """All 2n eigenvalues (1/s) and displacement parts of the eigenvectors of M, G, K.

    Solves the companion form [[0, I], [-M^-1 K, -M^-1 G]] z = lambda z.
    """
    n = M.shape[0]
    MiK = jnp.linalg.solve(M, K)
    MiG = jnp.linalg.solve(M, G)
    A = jnp.block([[jnp.zeros((n, n)), jnp.eye(n)], [-MiK, -MiG]])
    lam, Z = jnp.linalg.eig(A)
    return lam, Z[:n, :]


def is_stable_omega2(omega2):
    """True when no squared frequency is negative beyond round-off."""
    scale = jnp.max(jnp.abs(omega2))
    return jnp.all(omega2 >= -STABILITY_RTOL * scale)


def split_gyroscopic(lam, shapes):
    """Sort a stable gyroscopic spectrum into frequencies (Hz, ascending) and shapes.

    Keeps one eigenvalue of each conjugate pair (positive imaginary part).
    Returns ``(stable, frequencies_hz, shapes, unstable_eigenvalues)`` as numpy
    objects; with ``stable`` false the frequencies are empty.
    """
    import numpy as np

    lam = np.asarray(lam)
    shapes = np.asarray(shapes)
    scale = np.max(np.abs(lam))
    unstable = lam[lam.real > STABILITY_RTOL * scale]
    if unstable.size:
        return False, np.zeros(0), np.zeros((shapes.shape[0], 0)), unstable
    keep = lam.imag > 0
    freqs = lam.imag[keep] / (2 * np.pi)
    order = np.argsort(freqs)
    return True, freqs[order], shapes[:, keep][:, order], unstable


def ordinal(n: int) -> str:
    """1 -> '1st', 2 -> '2nd', 11 -> '11th', 23 -> '23rd'."""
    if 10 <= n % 100 <= 20:
        suffix = "th"
    else:
        suffix = {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{suffix}"
