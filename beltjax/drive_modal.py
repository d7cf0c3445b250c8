"""Modal analysis of a drive about its static (steady-motion) equilibrium.

The drive's reduced equations (:mod:`beltjax.drive`) are linearised by autodiff
at the equilibrium of :mod:`beltjax.statics`:

    M = J^T M_full J,   K = -dF_ii/dq_i,   G = -dF_ii/dq_i_dot

(``G`` is the gyroscopic matrix of the moving belt; ``K`` holds the elastic,
geometric and centrifugal stiffness).  At rest the problem is symmetric
(Cholesky + ``eigh``); at a belt speed it is gyroscopic and is solved in the
modal basis of (M, K) with the rigid-body modes (a drive whose pulleys are all
free turns as a whole at no cost) split off exactly: the belt's rigid sliding
has K v = 0 and G v = 0, so the remaining system has K positive definite and
the structured skew-symmetric route of :mod:`beltjax.modal` applies, with
exactly imaginary eigenvalues, under ``jit`` and ``vmap`` (Campbell diagrams).
A drive past its critical speed is reported unstable, never given frequencies.

Each mode is labelled by the share of its kinetic energy in each span's
transverse and longitudinal motion and in each rigid body's motion.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from beltjax import critical, drive, modal, statics
from beltjax.errors import BeltjaxError
from beltjax.scene import Scene
from beltjax.drive.effects import effects_of
from beltjax.mode_labels import (NAME_SHARE, RIGID_HZ, REPEATED_RTOL, _fine_profile, _half_waves, _labels,  # noqa: F401
                                 _ordinal, energy_shares, full_energy_shares, label_arrays, label_full,
                                 label_modes, localise_repeated)


def n_rigid_modes(scene: Scene) -> int:
    """Number of zero-frequency modes: 1 when every pulley is free (the belt turns as a whole) and
    no isolator ties the crank's rim to its hub."""
    return 1 if all(drive.is_free(scene)) and scene.isolator is None else 0


def linearise(qi, scene: Scene, inst, speed=0.0):
    """Reduced M (kg, kg m^2), G (kg m/s-like) and K (N/m, N m/rad...) at the state qi.

    M = J^T M_full J; K = -d F_ii(q_i, 0)/d q_i (the static residual, so geometric,
    elastic and centrifugal stiffness and the curvature of the kinematic map are
    all in); G = -J^T (dF/dq_dot) J (gamma is quadratic in the rates: no linear part).
    A drive without a single independent coordinate has no modes: a BeltjaxError naming
    model.fidelity.
    """
    if drive.n_independent(scene) == 0:
        raise BeltjaxError("model.fidelity: this drive has no coordinate that may move (every pulley is driven and "
                           "the rotational model's spans are bars), so it has no modes; give a pulley driven = "
                           "false, a tensioner, or fidelity = \"ancf\"", "model.fidelity")
    phi = lambda x: drive.full_coordinates(x, scene, inst)  # noqa: E731
    J = jax.jacfwd(phi)(qi)
    M = J.T @ drive.full_mass_matrix(scene, inst) @ J
    K = -jax.jacfwd(lambda q: drive.static_residual(q, scene, inst, speed))(qi)
    M = 0.5 * (M + M.T)
    K = 0.5 * (K + K.T)
    if effects_of(scene).moving_belt:
        q = phi(qi)
        c = drive.transport_speed(scene, inst, speed)
        Gf = -jax.jacfwd(lambda v: drive.full_forces(q, v, scene, inst, c))(jnp.zeros_like(q))
        G = J.T @ Gf @ J
        G = 0.5 * (G - G.T)
    else:
        G = jnp.zeros_like(M)
    return M, G, K


def rigid_mode(scene: Scene, inst):
    """The belt's rigid slide in independent coordinates (1 m of belt along the route).

    Every free pulley (and a decoupler's rotor) turns by 1 / (s R) rad, every interior span node moves 1 m along
    its span; with straight spans K v = 0 and G v = 0 exactly.
    """
    free = drive.is_free(scene)
    senses = np.asarray(scene.route.senses)
    rigid = [1.0 / (senses[i] * inst.radii[i]) for i, f in enumerate(free) if f]
    rigid += [1.0 / (senses[i] * inst.radii[i]) for i in drive.drive_of(scene).rotors]  # with their pulleys
    rigid += [jnp.zeros(())] * drive.layout_of(scene).coordinates  # the arm does not move
    rigid = jnp.stack(rigid) if rigid else jnp.zeros(0, inst.radii.dtype)  # (no free pulley: none)
    return jnp.concatenate([rigid, drive.spans_of(scene).rigid_slide(inst.span_tangent)])


def _complement(w):
    """Orthonormal basis (n, n-1) of the complement of the vector w (a Householder reflector)."""
    w = w / jnp.linalg.norm(w)
    e1 = jnp.zeros_like(w).at[0].set(1.0)
    sgn = jnp.where(w[0] >= 0, 1.0, -1.0)
    u = w + sgn * e1
    u = u / jnp.linalg.norm(u)
    H = jnp.eye(w.shape[0]) - 2.0 * jnp.outer(u, u)
    return H[:, 1:]


def _project_rigid(M, G, K, n_rigid, v0):
    if not n_rigid:
        return jnp.eye(M.shape[0]), M, G, K
    T = _complement(M @ v0)
    return T, T.T @ M @ T, T.T @ G @ T, T.T @ K @ T


def frequencies_from_matrices(M, G, K, n_rigid: int, gyroscopic: bool, v0=None):
    """Natural frequencies from linearised matrices: (stable, frequencies in Hz ascending, rigid modes first).

    M, G, K: mass [kg], gyroscopic [kg/s] and stiffness [N/m] matrices of the independent
    coordinates; n_rigid: number of rigid-body modes (0 or 1); gyroscopic: solve the
    gyroscopic problem (needs the rigid mode v0 when n_rigid is 1).  Pure JAX, vmap-able.
    """
    if not gyroscopic:
        omega2 = jnp.linalg.eigvalsh(_mass_normalised(M, K))
        f = jnp.sqrt(jnp.clip(omega2, 0.0, None)) / (2 * jnp.pi)
        return jnp.all(omega2[n_rigid:] > 0), f.at[:n_rigid].set(0.0)
    _, Mz, Gz, Kz = _project_rigid(M, G, K, n_rigid, v0)
    ok, omega = modal.skew_frequencies(0.5 * (Mz + Mz.T), 0.5 * (Gz - Gz.T), 0.5 * (Kz + Kz.T))
    return ok, jnp.concatenate([jnp.zeros(n_rigid), omega / (2 * jnp.pi)])


def _mass_normalised(M, K):
    Lc = jnp.linalg.cholesky(M)
    X = jax.scipy.linalg.solve_triangular(Lc, K, lower=True)
    A = jax.scipy.linalg.solve_triangular(Lc, X.T, lower=True)
    return 0.5 * (A + A.T)


def _modes_core(M, G, K, n_rigid: int, gyroscopic: bool, v0=None):
    """Pure-JAX modes: (stable, freqs_hz ascending, complex shapes (n, n)).

    Rigid modes first (0 Hz).  Stable means every flexible omega^2 > 0 (K
    positive definite on the flexible subspace).  The gyroscopic route needs the
    rigid mode ``v0`` when ``n_rigid`` is 1 (see :func:`rigid_mode`): the system is
    restricted to the M-orthogonal complement of v0, where K is positive definite.
    """
    if not gyroscopic:
        omega2, V = modal.symmetric_modes(M, K)
        stable = jnp.all(omega2[n_rigid:] > 0)
        f = jnp.sqrt(jnp.clip(omega2, 0.0, None)) / (2 * jnp.pi)
        f = f.at[:n_rigid].set(0.0)
        return stable, f, V.astype(jnp.complex128)
    T, Mz, Gz, Kz = _project_rigid(M, G, K, n_rigid, v0)
    ok, omega, Z = modal._skew_modes(0.5 * (Mz + Mz.T), 0.5 * (Gz - Gz.T), 0.5 * (Kz + Kz.T))
    f = jnp.concatenate([jnp.zeros(n_rigid), omega / (2 * jnp.pi)])
    rig = (v0 / jnp.max(jnp.abs(v0)))[:, None] if n_rigid else jnp.zeros((M.shape[0], 0))
    shapes = jnp.concatenate([rig.astype(jnp.complex128), T @ Z], axis=1)
    return ok, f, shapes


def tracking_modes(M, G, K, n_rigid: int, gyroscopic: bool, v0, k: int):
    """The lowest ``k`` modes with shapes for mode tracking, at the cost of the frequencies alone.

    Returns ``(stable, freqs (k,) Hz ascending, X (n, c) complex shapes, owner (c,) int)``: column
    j of X belongs to mode owner[j] (one column per mode without the gyroscopic terms, two with
    them: :func:`beltjax.modal.skew_mode_planes`; the columns of repeated modes together span
    their eigenspace, see :func:`beltjax.mode_tracking.mode_basis`).  Arguments as
    :func:`frequencies_from_matrices`, whose frequencies these are.  Pure JAX (jit, vmap).
    """
    if not gyroscopic:
        omega2, V = modal.symmetric_modes(M, K)
        f = (jnp.sqrt(jnp.clip(omega2, 0.0, None)) / (2 * jnp.pi)).at[:n_rigid].set(0.0)
        return jnp.all(omega2[n_rigid:] > 0), f[:k], V[:, :k].astype(jnp.complex128), jnp.arange(k)
    T, Mz, Gz, Kz = _project_rigid(M, G, K, n_rigid, v0)
    ok, omega, Z = modal.skew_mode_planes(0.5 * (Mz + Mz.T), 0.5 * (Gz - Gz.T), 0.5 * (Kz + Kz.T), k - n_rigid)
    f = jnp.concatenate([jnp.zeros(n_rigid), omega[: k - n_rigid] / (2 * jnp.pi)])
    rig = (v0 / jnp.max(jnp.abs(v0)))[:, None] if n_rigid else jnp.zeros((M.shape[0], 0))
    X = jnp.concatenate([rig.astype(jnp.complex128), T @ Z], axis=1)
    owner = jnp.concatenate([jnp.zeros(n_rigid, int), n_rigid + jnp.repeat(jnp.arange(k - n_rigid), 2)])
    return ok, f, X, owner


def tracking_shapes(scene: Scene, qi, inst, speed, k: int, gyroscopic: bool, full: bool = True):
    """Modes about the equilibrium (qi, inst) at belt speed ``speed`` [m/s] for tracking (pure JAX).

    Returns a dict: stable, freqs (k,) [Hz], owner (c,), W (n, c) = L^T X with M = L L^T (the
    mass-whitened shapes: W_a^H W_b = x_a^H M x_b, the inner product of a mass-weighted MAC),
    and with ``full`` the full-coordinate shapes V (n_full, c) = J X and :func:`label_arrays`
    (what :func:`label_full` needs to label them).
    """
    M, G, K = linearise(qi, scene, inst, speed)
    stable, f, X, owner = tracking_modes(M, G, K, n_rigid_modes(scene), gyroscopic, k=k,
                                         v0=rigid_mode(scene, inst))
    out = dict(stable=stable, freqs=f, owner=owner, W=jnp.linalg.cholesky(M).T @ X)
    if full:
        J = jax.jacfwd(lambda x: drive.full_coordinates(x, scene, inst))(qi)
        out.update(V=J @ X, **label_arrays(scene, inst))
    return out


@partial(jax.jit, static_argnames=("gyroscopic",))
def modes_at(scene: Scene, qi, inst, speed, gyroscopic: bool):
    """Modes about a given equilibrium (qi, inst) at belt speed ``speed`` [m/s], jitted.

    Returns a dict: stable, freqs [Hz], complex shapes, the matrices M, G, K and the
    kinematic Jacobian J of all coordinates with respect to the independent ones.
    """
    M, G, K = linearise(qi, scene, inst, speed)
    stable, f, shapes = _modes_core(M, G, K, n_rigid_modes(scene), gyroscopic, rigid_mode(scene, inst))
    J = jax.jacfwd(lambda x: drive.full_coordinates(x, scene, inst))(qi)
    return dict(stable=stable, freqs=f, shapes=shapes, M=M, G=G, K=K, J=J)


class SpeedModes(NamedTuple):
    """The drive at one belt speed (:func:`at_speed`): equilibrium qi and installation, whether
    the statics converged, whether a span is past its critical speed, whether the linearised
    drive is stable, its frequencies (Hz, ascending, rigid modes included) and M, G, K."""

    qi: jax.Array
    inst: drive.Installation
    converged: jax.Array
    supercritical: jax.Array
    stable: jax.Array
    freqs: jax.Array
    M: jax.Array | None
    G: jax.Array | None
    K: jax.Array | None
    tracking: dict | None = None


def at_speed(scene: Scene, speed, inst=None, steps: int = 1, gyroscopic: bool | None = None, track: int = 0,
             full: bool = False) -> SpeedModes:
    """Statics -> linearisation -> frequencies at belt speed ``speed`` (m/s): the one pipeline
    of modal analysis, Campbell diagrams, sweeps, optimisation and the modal fit.

    inst: the installation (default: solved from the scene); steps: speed steps of the statics
    from rest; gyroscopic: whether G enters the eigen-problem (default: the belt moves, i.e.
    ``transport`` is listed).  With ``track`` = k > 0 the lowest k modes come from the tracking
    eigen-solver with their shapes (:func:`tracking_shapes`, ``full`` as there) in ``tracking``,
    and M, G, K are None.  The linearisation is about the operating point when the scene has
    lasting loads (:func:`beltjax.drive.lasting_loads`: the mean loads at this speed), else about
    the unloaded state.  Pure, vmappable, differentiable (statics by implicit
    differentiation, symmetric eigenvalues)."""
    qi, inst, info = statics.equilibrium(scene, inst, speed=speed, steps=steps, loaded=drive.lasting_loads(scene))
    sup = critical.supercritical(scene, qi, inst, speed)
    if track:
        t = tracking_shapes(scene, qi, inst, speed, track, _gyroscopic(scene, gyroscopic), full=full)
        return SpeedModes(qi, inst, info[0] > 0.5, sup, t["stable"], t["freqs"], None, None, None, t)
    stable, f, M, G, K = frequencies_about(scene, qi, inst, speed, gyroscopic)
    return SpeedModes(qi, inst, info[0] > 0.5, sup, stable, f, M, G, K)


def frequencies_about(scene: Scene, qi, inst, speed, gyroscopic: bool | None = None):
    """Linearisation -> frequencies about a solved equilibrium (qi, inst) at belt speed ``speed``
    (m/s), the second half of :func:`at_speed`: (stable, freqs Hz ascending, M, G, K)."""
    M, G, K = linearise(qi, scene, inst, speed)
    stable, f = frequencies_from_matrices(M, G, K, n_rigid_modes(scene), _gyroscopic(scene, gyroscopic),
                                          rigid_mode(scene, inst))
    return stable, f, M, G, K


def _gyroscopic(scene: Scene, gyroscopic: bool | None) -> bool:
    """Whether G enters the eigen-problem: as asked, else whether the belt moves (``transport``)."""
    return effects_of(scene).moving_belt if gyroscopic is None else gyroscopic


def frequencies(scene: Scene, speed=None):
    """Natural frequencies (Hz, ascending, rigid modes included) at belt speed ``speed`` (m/s).

    Pure and differentiable (:func:`at_speed`); NaN where the drive is unstable.  Use on
    distinct eigenvalues or symmetric functions of repeated ones for gradients.
    """
    speed = drive.belt_speed(scene) if speed is None else speed
    m = at_speed(scene, speed)
    return jnp.where(m.stable, m.freqs, jnp.nan)


# --------------------------------------------------------------------------- user-facing result


@dataclass
class ModalResult:
    """Modes of a drive (see :func:`analyse_modes`).

    frequencies_hz ascending (rigid modes included, 0 Hz); labels; stable;
    unstable_eigenvalues (1/s) when not stable; energy_shares: name -> per-mode
    kinetic-energy share; speed_m_s; mode_shapes: (n_independent, n_modes),
    real parts, unit max; statics: the :class:`beltjax.statics.StaticResult`;
    unstable_reason: why the drive is reported unstable (None when stable): past the
    critical speed (a span's force on the pulleys <= 0, :mod:`beltjax.critical`), or
    modes that grow.
    """

    frequencies_hz: np.ndarray
    labels: list[str]
    stable: bool
    unstable_eigenvalues: np.ndarray
    energy_shares: dict
    speed_m_s: float
    n_independent: int
    mode_shapes: np.ndarray = field(repr=False)
    statics: object = field(repr=False, default=None)
    unstable_reason: str | None = None

    def to_json(self, n_modes: int | None = None) -> dict:
        """modal.json contents (first n_modes modes, all by default)."""
        k = len(self.frequencies_hz) if n_modes is None else min(n_modes, len(self.frequencies_hz))
        return {
            "speed_m_s": self.speed_m_s,
            "stable": self.stable,
            "unstable_reason": self.unstable_reason,
            "n_independent_coordinates": self.n_independent,
            "frequencies_hz": [float(x) for x in self.frequencies_hz[:k]],
            "labels": self.labels[:k],
            "energy_shares": {name: [round(float(x), 4) for x in v[:k]] for name, v in self.energy_shares.items()},
            "unstable_eigenvalues": [[float(z.real), float(z.imag)] for z in self.unstable_eigenvalues],
        }


#: why a drive whose linearised modes grow is reported unstable
GROWING = ("the linearised drive has modes that grow (or that only gyroscopic coupling holds, "
           "which any damping destroys): no natural frequencies")


def analyse_modes(scene: Scene, speed: float | None = None) -> ModalResult:
    """Natural frequencies, labelled mode shapes and stability of a drive at belt speed ``speed`` (m/s).

    Runs the statics first (its one-line errors apply).  At a speed with the
    ``transport`` effect the gyroscopic problem is solved; an unstable drive
    gets ``stable=False``, its unstable eigenvalues, no frequencies and the reason
    (``unstable_reason``).  A drive past its critical speed (a span's force on the
    pulleys <= 0: :mod:`beltjax.critical`) is unstable whatever the eigenvalues say:
    the rotational model's massless spans, for one, keep positive stiffness there.  The
    scene and the speed are checked as in :func:`beltjax.statics.analyse_statics`.
    """
    st = statics.analyse_statics(scene, speed, allow_supercritical=True, with_unloaded=False)  # checks the scene, the speed
    v = st.speed_m_s
    gyro = effects_of(scene).moving_belt and v != 0.0
    qi = jnp.asarray(st.qi)
    out = modes_at(drive.statics_scene(scene), qi, st.inst, v, gyro)
    stable = bool(out["stable"])
    n = drive.n_independent(scene)
    freqs = np.asarray(out["freqs"])
    shapes = np.asarray(out["shapes"])
    unstable = np.zeros(0, complex)
    if not stable:
        # K is not positive definite on the flexible subspace: the companion form decides
        # there (gyroscopic stabilisation counts as unstable, see beltjax.modal)
        nr = n_rigid_modes(scene)
        M, G, K = (np.asarray(out[k]) for k in ("M", "G", "K"))
        T, rig = np.eye(n), np.zeros((n, 0))
        if nr:  # the M-orthogonal complement of the rigid mode v0 (numpy: no compilation)
            v0 = np.asarray(rigid_mode(scene, st.inst))
            w = M @ v0 / np.linalg.norm(M @ v0)
            u = w + np.copysign(1.0, w[0]) * np.eye(n)[0]
            T = (np.eye(n) - 2.0 * np.outer(u, u) / (u @ u))[:, 1:]
            rig = (v0 / np.max(np.abs(v0)))[:, None]
        ok, f, Z, unstable = modal.companion_modes(T.T @ M @ T, T.T @ G @ T, T.T @ K @ T)
        if not ok:
            return ModalResult(np.zeros(0), [], False, unstable, {}, v, n, np.zeros((n, 0)), st,
                               st.supercritical or GROWING)
        stable = True  # K semi-definite up to round-off (e.g. exactly at a critical speed)
        freqs = np.concatenate([np.zeros(nr), f])
        shapes = np.concatenate([rig.astype(complex), T @ Z], axis=1)
    if st.supercritical is not None:
        return ModalResult(np.zeros(0), [], False, unstable, {}, v, n, np.zeros((n, 0)), st, st.supercritical)
    if not gyro and bool(out["stable"]):  # real modes: each repeated eigenspace in the basis its spans separate
        shapes = localise_repeated(freqs, shapes, out["M"], out["J"], scene, st.inst).astype(complex)
    labels, shares = label_modes(freqs, shapes, qi, scene, st.inst, out["J"])
    Vr = np.real(shapes * np.exp(-1j * np.angle(np.sum(shapes**2, axis=0)) / 2))
    Vr = Vr / np.maximum(np.max(np.abs(Vr), axis=0, keepdims=True), 1e-300)
    return ModalResult(freqs, labels, True, np.zeros(0, complex), shares, v, n, Vr, st)

