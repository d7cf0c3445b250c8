"""Natural frequencies and what each mode is, inside the compiled loss.

A resonance objective with ``modes = "span"`` watches the transverse span modes.  Sorted
frequencies change places as the layout and the speed change (a span mode passes a rotational
one), so the selection is made again at every sampled speed and every evaluation from the
modes' own shapes: each mode's kinetic energy is split into span transverse, span longitudinal
and body (pulleys, arm) motion as :func:`beltjax.drive_modal.energy_shares` splits it (the same
consistent span mass, the same body masses), and its weight is

    w = clip(1 + (tr - max(lo, ro)) / SPAN_RAMP, 0, 1)

with tr, lo, ro its transverse, longitudinal and body shares: exactly 1 for every mode that
:func:`~beltjax.drive_modal.label_modes` calls transverse (tr the largest share; so ``w == 1``
is the label's test, used by the exact check and the reports), falling to 0 for a mode whose
transverse share trails by SPAN_RAMP or more.  A watched mode thus always counts fully in the
smooth loss (a zero loss means a clear band), and a mode about to become a span mode (at a
veering, its transverse share rising) counts in part, so the loss stays continuous as the
label changes.  The weights are held out of the gradient (``stop_gradient``); they are flat
(0 or 1) outside the ramp, so there the gradient of the loss is exact.

The frequencies come from one symmetric eigen-decomposition per speed, with vectors (the
vectors give the shapes): the eigenvectors U of the matrix A (held out of the gradient) and the
eigenvalues as the Rayleigh quotients u^T A u of the differentiable A.  Their value is the
eigenvalue and their derivative u^T dA u is the eigenvalue's derivative (the formula
``eigvalsh``'s own derivative uses), so values and gradients are those of
:func:`beltjax.drive_modal.frequencies_from_matrices`, at no measurable cost: the gradient of
``eigvalsh`` runs ``eigh`` with vectors anyway (the example's value and gradient, 8 elements, 9
speeds: 262-340 ms min-median with the span weights against 291-381 ms with ``eigvalsh`` and
no weights, compile 107 against 104 s, on the 2-core machine at a load of 2-5).  Repeated eigenvalues (equal spans): each
quotient's derivative is that of an arbitrary basis of the eigenspace, but the spans' modes are
alike (same weight) and a symmetric function of the pair has the exact gradient (DESIGN facts
on repeated eigenvalues; :mod:`beltjax.optimize`).

Gyroscopic problem: the real skew matrix S of :func:`beltjax.modal._skew_matrix` has the
eigenvalues +-i omega, so A = S^T S has each omega^2 twice; the two real vectors of a pair span
the mode's invariant plane and the energy split of the complex mode is the sum over the two
(any orthonormal basis of the plane gives the same sum).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from beltjax import drive, drive_modal, modal, span
from beltjax.scene import Scene

#: width of the weight's ramp below a span mode, as a margin of kinetic-energy share (module docstring)
SPAN_RAMP = 0.1

_sg = jax.lax.stop_gradient


def class_energies(V, scene: Scene, inst):
    """Kinetic energies (tr, lo, ro), each (k,), of the real columns V (n_full, k) of velocities
    in full coordinates: span transverse, span longitudinal, bodies (J, any scale)."""
    n = len(scene.route.order)
    N = drive.span_elements(scene)
    ns = 4 * (N + 1)
    Le = drive.element_length(scene, inst)
    t = inst.span_tangent
    nrm = jnp.stack([-t[:, 1], t[:, 0]], axis=1)
    rhoA = drive.spans_of(scene).mass_per_length(scene.belt.rhoA)
    tr = lo = jnp.zeros(V.shape[1])
    for s in range(n):
        Ms = span.span_component_mass(rhoA, Le[s], N)
        blk = V[s * ns:(s + 1) * ns].reshape(N + 1, 2, 2, -1)  # node, (pos, slope), (x, y), column
        ul = jnp.einsum("nkdm,d->nkm", blk, t[s]).reshape(2 * (N + 1), -1)
        ut = jnp.einsum("nkdm,d->nkm", blk, nrm[s]).reshape(2 * (N + 1), -1)
        lo = lo + jnp.einsum("im,ij,jm->m", ul, Ms, ul)
        tr = tr + jnp.einsum("im,ij,jm->m", ut, Ms, ut)
    B = V[n * ns:].reshape(-1, 3, V.shape[1])
    mass = jnp.reshape(drive.body_masses(scene, inst), (-1, 3))
    ro = jnp.einsum("bkm,bk,bkm->m", B, mass, B)
    return tr, lo, ro


def span_weight(tr, lo, ro):
    """Weight (0..1) of a mode as a span (transverse) mode from its class energies (module docstring)."""
    total = jnp.where(tr + lo + ro > 0, tr + lo + ro, 1.0)
    d = (tr - jnp.maximum(lo, ro)) / total
    return jnp.clip(1.0 + d / SPAN_RAMP, 0.0, 1.0)


def _rayleigh(A):
    """(values, vectors) of the symmetric A: vectors from ``eigh`` held out of the gradient,
    values as the differentiable Rayleigh quotients (ascending)."""
    _, U = jnp.linalg.eigh(_sg(A))
    U = _sg(U)
    return jnp.einsum("ik,ij,jk->k", U, A, U), U


def frequencies_and_span_weights(M, G, K, J, n_rigid: int, gyroscopic: bool, v0, scene: Scene, inst):
    """(stable, frequencies (n,) Hz ascending, span weights (n,)) of the linearised drive.

    M, G, K: :func:`beltjax.drive_modal.linearise`; J: d full coordinates / d independent ones
    at the state; n_rigid, gyroscopic, v0: as :func:`beltjax.drive_modal.frequencies_from_matrices`
    (same frequencies, same stability test).  Rigid modes first (0 Hz, weight 0).  Pure JAX.
    """
    if not gyroscopic:
        Lc = jnp.linalg.cholesky(M)
        X = jax.scipy.linalg.solve_triangular(Lc, K, lower=True)
        A = jax.scipy.linalg.solve_triangular(Lc, X.T, lower=True)
        omega2, U = _rayleigh(0.5 * (A + A.T))
        stable = jnp.all(omega2[n_rigid:] > 0)
        f = (jnp.sqrt(jnp.clip(omega2, 0.0, None)) / (2 * jnp.pi)).at[:n_rigid].set(0.0)
        shapes = jax.scipy.linalg.solve_triangular(_sg(Lc).T, U, lower=False)
        tr, lo, ro = class_energies(_sg(J) @ shapes, scene, _sg(inst))
        w = span_weight(tr, lo, ro).at[:n_rigid].set(0.0)
        return stable, f, _sg(w)
    T, Mz, Gz, Kz = drive_modal._project_rigid(M, G, K, n_rigid, v0)
    S, Lb, finite = modal._skew_matrix(0.5 * (Mz + Mz.T), 0.5 * (Gz - Gz.T), 0.5 * (Kz + Kz.T))
    w2, U = _rayleigh(S.T @ S)
    stable = finite & jnp.all(w2 > 0)
    omega = jnp.sqrt(jnp.clip(0.5 * (w2[0::2] + w2[1::2]), 0.0, None))
    n = Mz.shape[0]
    LM = _sg(Lb)[n:, n:]  # diag(K, M) = Lb Lb^T: the lower half of z = Lb^T y is LM^T x_dot
    xdot = _sg(T) @ jax.scipy.linalg.solve_triangular(LM.T, U[n:], lower=False)
    tr, lo, ro = (e[0::2] + e[1::2] for e in class_energies(_sg(J) @ xdot, scene, _sg(inst)))
    f = jnp.concatenate([jnp.zeros(n_rigid), omega / (2 * jnp.pi)])
    w = jnp.concatenate([jnp.zeros(n_rigid), span_weight(tr, lo, ro)])
    return stable, f, _sg(w)
