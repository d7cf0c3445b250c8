"""Eigen-analysis of linearised mechanical systems M x'' + G x' + K x = 0.

Generic over the system: the span analysis and later the drive models hand
their reduced matrices (from autodiff) to these functions.

* ``symmetric_modes`` (G = 0): Cholesky of M and ``eigh``; differentiable.
* ``gyroscopic_modes`` (G skew, from belt transport): the first-order
  companion form and a general eigen-solver.

A system is stable when no eigenvalue has a positive real part beyond the
round-off floor and, with G != 0, K is positive definite; unstable eigenvalues
are returned, frequencies are not invented for an unstable system.

Gyroscopic stabilisation is not stability here.  Past a critical speed K can
turn indefinite while every eigenvalue of the undamped M, G, K stays imaginary
(an even number of negative stiffnesses, e.g. two equal spans or a nearly
bending-free span a little past sqrt(T/rhoA)).  By the Kelvin-Tait-Chetaev
theorem any damping (belt, bearings: always present) then makes the system
unstable: the modes of negative energy omega^2 x^H M x + x^H K x grow, at the
rate -omega^2 x^H D x / E for a damping matrix D.  Those modes are reported as
the unstable eigenvalues (purely imaginary) and ``stable`` is False, as it is
in the Cholesky-based routes (:func:`skew_frequencies`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

#: Relative size (to the largest |eigenvalue|) above which a positive real
#: part (or a negative omega^2) counts as an instability and not round-off.
STABILITY_RTOL = 1e-7
#: Relative size (to the largest |omega^2| of K against M) beyond which a negative
#: stiffness eigenvalue counts as real and not round-off (eigvalsh is accurate to ~1e-15).
STIFFNESS_RTOL = 1e-12


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


def _skew_matrix(M, G, K):
    """The real skew matrix S = L^-1 [[0, K], [-K, -G]] L^-T with diag(K, M) = L L^T.

    Its eigenvalues are +-i omega, the circular frequencies of M x'' + G x' + K x = 0
    (K, M positive definite).  Returns (S, L, finite): finite is False when a
    Cholesky factor failed (K or M not positive definite).
    """
    n = M.shape[0]
    LK = jnp.linalg.cholesky(K)
    LM = jnp.linalg.cholesky(M)
    Z = jnp.zeros((n, n))
    Lb = jnp.block([[LK, Z], [Z, LM]])
    A = jnp.block([[Z, K], [-K, -G]])
    X = jax.scipy.linalg.solve_triangular(Lb, A, lower=True)
    S = jax.scipy.linalg.solve_triangular(Lb, X.T, lower=True).T
    return 0.5 * (S - S.T), Lb, jnp.all(jnp.isfinite(LK)) & jnp.all(jnp.isfinite(LM))


@jax.jit
def _skew_modes(M, G, K):
    n = M.shape[0]
    S, Lb, finite = _skew_matrix(M, G, K)
    w, U = jnp.linalg.eigh(1j * S)  # S v = i omega v  <=>  (i S) v = -omega v
    omega = -w[:n][::-1]  # the n negative w, as ascending omega > 0
    U = U[:, :n][:, ::-1]
    Zs = jax.scipy.linalg.solve_triangular(Lb.T.astype(U.dtype), U, lower=False)
    ok = finite & jnp.all(omega > 0)
    return ok, omega, Zs[:n, :]


def skew_frequencies(M, G, K):
    """Circular frequencies only (rad/s, ascending) of M x'' + G x' + K x = 0, K and M > 0.

    The real skew matrix S of :func:`_skew_matrix` has eigenvalues +-i omega, so
    S^T S = -S^2 is symmetric with eigenvalues omega^2, each twice: a real
    ``eigvalsh`` (no eigenvectors, no complex arithmetic) instead of the complex
    Hermitian ``eigh``, about 3x cheaper.  Returns (ok, omega); ok is False when a
    Cholesky factor fails (K not positive definite: unstable or rigid modes).
    """
    S, _, finite = _skew_matrix(M, G, K)
    w2 = jnp.linalg.eigvalsh(S.T @ S)
    omega = jnp.sqrt(jnp.clip(w2[0::2], 0.0, None))
    ok = finite & jnp.all(w2 > 0)
    return ok, omega


def skew_mode_planes(M, G, K, k: int):
    """The lowest ``k`` modes of M x'' + G x' + K x = 0 (K, M > 0) with shapes, at the cost of
    :func:`skew_frequencies` (a real ``eigh`` of S^T S, vectors included, instead of the complex
    ``eigh`` of i S).

    Each circular frequency omega is an eigenvalue of S^T S twice, its eigenvectors a spanning the
    real plane {Re u, Im u} of the mode's state eigenvector u (S u = i omega u); u = a - i S a / omega
    for any a in that plane.  Returns ``(ok, omega (n,) rad/s ascending, X (n, 2k) complex
    displacement shapes)``: columns 2j and 2j+1 come from the two vectors of mode j's plane, so
    they are the same mode up to a complex factor; where frequencies repeat, the columns of the
    repeated modes together span their eigenspace (pick a basis afterwards: several real vectors
    of one eigenspace may give the same complex direction).  ok as in :func:`skew_frequencies`.
    """
    n = M.shape[0]
    S, Lb, finite = _skew_matrix(M, G, K)
    w2, A = jnp.linalg.eigh(S.T @ S)
    omega = jnp.sqrt(jnp.clip(w2[0::2], 0.0, None))
    a = A[:, : 2 * k]
    w = jnp.repeat(omega[:k], 2)
    z = a - 1j * (S @ a) / jnp.where(w > 0, w, 1.0)
    Z = jax.scipy.linalg.solve_triangular(Lb.T.astype(z.dtype), z, lower=False)
    return finite & jnp.all(w2 > 0), omega, Z[:n]


def gyroscopic_modes(M, G, K):
    """Modes of M x'' + G x' + K x = 0 (G skew): ``(stable, freqs_hz, shapes, unstable)``.

    While K is positive definite the system is stable and the structured route is
    used: with B = diag(K, M) = L L^T the pencil becomes the real skew matrix
    S = L^-1 [[0, K], [-K, -G]] L^-T, whose eigenvalues i omega come from the
    Hermitian ``eigh`` of i S (twice as fast as a general eigen-solver, and the
    eigenvalues are exactly imaginary).  Otherwise (past the critical speed, rigid
    body modes) the companion form and a general eigen-solver decide stability.
    """
    import numpy as np

    ok, omega, shapes = _skew_modes(M, G, K)
    if bool(ok):
        return True, np.asarray(omega) / (2 * np.pi), np.asarray(shapes), np.zeros(0, complex)
    return companion_modes(M, G, K)


def stiffness_is_definite(M, K) -> bool:
    """True when K is positive semi-definite (against M) up to round-off (numpy bool)."""
    import numpy as np

    M, K = np.asarray(M), np.asarray(K)
    Lc = np.linalg.cholesky(M)
    A = np.linalg.solve(Lc, np.linalg.solve(Lc, K).T)
    omega2 = np.linalg.eigvalsh(0.5 * (A + A.T))
    return bool(omega2[0] >= -STIFFNESS_RTOL * np.max(np.abs(omega2)))


def companion_modes(M, G, K):
    """Modes of M x'' + G x' + K x = 0 by the companion form and a general eigen-solver.

    Returns ``(stable, freqs_hz, shapes, unstable)`` as :func:`split_gyroscopic`; a spectrum
    that is imaginary only by gyroscopic stabilisation (K indefinite) is unstable, with
    its negative-energy modes as the unstable eigenvalues (see the module docstring).
    """
    import numpy as np

    M, G, K = np.asarray(M), np.asarray(G), np.asarray(K)
    n = M.shape[0]
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(M, K), -np.linalg.solve(M, G)]])
    lam, Z = np.linalg.eig(A)  # numpy: no compilation for a fallback route
    Z = Z[:n, :]
    stable, freqs, shapes, unstable = split_gyroscopic(lam, Z)
    if not stable or stiffness_is_definite(M, K):
        return stable, freqs, shapes, unstable
    keep = lam.imag > 0
    lam, Z = lam[keep], Z[:, keep]
    w2 = lam.imag**2
    m = np.real(np.einsum("im,ij,jm->m", Z.conj(), M, Z))
    k = np.real(np.einsum("im,ij,jm->m", Z.conj(), K, Z))
    energy = (w2 * m + k) / (w2 * m + np.abs(k))  # in [-1, 1]
    negative = energy < 0
    if not np.any(negative):  # round-off hid the sign: the least positive energy
        negative = energy == np.min(energy)
    return False, np.zeros(0), np.zeros((Z.shape[0], 0)), lam[negative]


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
