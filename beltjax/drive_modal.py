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

import jax
import jax.numpy as jnp
import numpy as np

from beltjax import ancf, drive, modal, span, statics
from beltjax.scene import Scene
from beltjax.drive.effects import effects_of

#: a mode below this frequency (Hz) is a rigid-body mode
RIGID_HZ = 1e-2
#: share of a class's energy above which a span/body is named in a label
NAME_SHARE = 0.25


def n_rigid_modes(scene: Scene) -> int:
    """Number of zero-frequency modes: 1 when every pulley is free (the belt turns as a whole)."""
    return 1 if all(drive.is_free(scene)) else 0


def linearise(qi, scene: Scene, inst, speed=0.0):
    """Reduced M (kg, kg m^2), G (kg m/s-like) and K (N/m, N m/rad...) at the state qi.

    M = J^T M_full J; K = -d F_ii(q_i, 0)/d q_i (the static residual, so geometric,
    elastic and centrifugal stiffness and the curvature of the kinematic map are
    all in); G = -J^T (dF/dq_dot) J (gamma is quadratic in the rates: no linear part).
    """
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

    Every free pulley turns by 1 / (s R) rad, every interior span node moves 1 m along
    its span; with straight spans K v = 0 and G v = 0 exactly.
    """
    free = drive.is_free(scene)
    senses = np.asarray(scene.route.senses)
    rigid = [1.0 / (senses[i] * inst.radii[i]) for i, f in enumerate(free) if f]
    if scene.tensioner is not None:
        rigid.append(jnp.zeros(()))
    if not drive.flexible(scene):
        return jnp.stack(rigid)
    N = scene.model.elements_per_span
    n = len(scene.route.order)
    node = jnp.concatenate([inst.span_tangent, jnp.zeros((n, 2))], axis=1)  # (n, 4): position, slope
    spans = jnp.concatenate(
        [jnp.zeros((n, 2)), jnp.tile(node, (1, N - 1)), jnp.zeros((n, 2))], axis=1
    )
    return jnp.concatenate([jnp.stack(rigid), spans.reshape(-1)])


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


def frequencies(scene: Scene, speed=None):
    """Natural frequencies (Hz, ascending, rigid modes included) at belt speed ``speed`` (m/s).

    Pure and differentiable (statics by implicit differentiation, symmetric
    eigenvalues); NaN where the drive is unstable.  Use on distinct
    eigenvalues or symmetric functions of repeated ones for gradients.
    """
    speed = drive.belt_speed(scene) if speed is None else speed
    qi, inst, _ = statics.equilibrium(scene, speed=speed)
    M, G, K = linearise(qi, scene, inst, speed)
    gyro = effects_of(scene).moving_belt
    stable, f = frequencies_from_matrices(M, G, K, n_rigid_modes(scene), gyro, rigid_mode(scene, inst))
    return jnp.where(stable, f, jnp.nan)


# --------------------------------------------------------------------------- labels


def _ordinal(n):
    return modal.ordinal(int(n))


def _half_waves(w):
    """Half-waves of a displacement profile: interior nodes + 1.

    Real shapes: sign changes (ignoring values under 10 % of the maximum).  Complex
    modes of a moving belt carry a travelling phase along the span, so the real
    part's sign changes over-count; there a node is an interior local minimum of
    |w| under 35 % of its maximum (the standing-wave nodes).
    """
    w = np.asarray(w)
    a = np.abs(w)
    if a.size < 3 or np.max(a) == 0:
        return 1
    if np.max(np.abs(np.imag(w))) <= 1e-9 * np.max(a):
        r = np.real(w)
        s = np.sign(r[np.abs(r) > 0.1 * np.max(a)])
        return int(np.sum(s[1:] != s[:-1])) + 1
    inner = (a[1:-1] < a[:-2]) & (a[1:-1] <= a[2:]) & (a[1:-1] < 0.35 * np.max(a))
    return int(np.sum(inner)) + 1


def _fine_profile(u, Le, N, per_element: int = 16):
    """Displacement profile along a span from nodal (value, slope) pairs, by the cubic shape functions."""
    x = (np.arange(per_element) + 0.5) / per_element
    S = np.asarray(ancf.shape_functions(x, Le)).T  # (per_element, 4), the elements' own
    nodes = u.reshape(N + 1, 2, -1)
    elem = np.concatenate([nodes[:-1], nodes[1:]], axis=1)  # (N, 4, modes)
    return np.einsum("pk,ekm->epm", S, elem).reshape(N * per_element, -1)


def energy_shares(shapes, qi, scene: Scene, inst, J=None):
    """Kinetic-energy shares of each mode: dict name -> (n_modes,) array summing to 1.

    Names: "<span> transverse", "<span> longitudinal" per span, and each body's
    name (pulleys, "tensioner" idler, "tensioner arm").  Also returns the
    per-span transverse and longitudinal profiles, (n_modes, n_spans, n_points).
    """
    if J is None:
        J = jax.jacfwd(lambda x: drive.full_coordinates(x, scene, inst))(jnp.asarray(qi))
    V = np.asarray(J) @ np.asarray(shapes)  # full-coordinate shapes (complex)
    return full_energy_shares(V, scene, label_arrays(scene, inst))


def label_arrays(scene: Scene, inst) -> dict:
    """What labels need of an equilibrium besides the shapes (pure JAX): element lengths Le (m)
    per span, span tangents, and the bodies' mass diagonal body_mass (kg, kg m^2)."""
    return dict(Le=drive.element_length(scene, inst), tangent=inst.span_tangent,
                body_mass=drive.body_masses(scene, inst))


def full_energy_shares(V, scene: Scene, arrays: dict):
    """:func:`energy_shares` of full-coordinate shapes V (n_full, n_modes) with :func:`label_arrays`."""
    V = np.asarray(V)
    n = len(scene.route.order)
    N = drive.span_elements(scene)
    ns = 4 * (N + 1)
    Le = np.asarray(arrays["Le"])
    t = np.asarray(arrays["tangent"])
    nrm = np.stack([-t[:, 1], t[:, 0]], axis=1)
    shares, trans, longi = {}, [], []
    names = drive.span_names(scene)
    for s in range(n):
        Ms = np.asarray(span.span_component_mass(float(scene.belt.rhoA) if drive.flexible(scene) else 0.0,
                                                   float(Le[s]), N))
        blk = V[s * ns : (s + 1) * ns].reshape(N + 1, 2, 2, -1)  # node, (pos, slope), (x, y), mode
        ul = np.einsum("nkdm,d->nkm", blk, t[s]).reshape(2 * (N + 1), -1)
        ut = np.einsum("nkdm,d->nkm", blk, nrm[s]).reshape(2 * (N + 1), -1)
        shares[f"{names[s]} longitudinal"] = np.real(np.einsum("im,ij,jm->m", ul.conj(), Ms, ul))
        shares[f"{names[s]} transverse"] = np.real(np.einsum("im,ij,jm->m", ut.conj(), Ms, ut))
        trans.append(_fine_profile(ut, Le[s], N))
        longi.append(_fine_profile(ul, Le[s], N))
    B = V[n * ns :].reshape(-1, 3, V.shape[1])
    mass = np.asarray(arrays["body_mass"]).reshape(-1, 3)
    for b, name in enumerate(drive.body_names(scene)):
        shares[name] = np.real(np.einsum("km,k,km->m", B[b].conj(), mass[b], B[b]))
    total = sum(shares.values())
    total = np.where(total > 0, total, 1.0)
    shares = {k: v / total for k, v in shares.items()}
    return shares, np.stack(trans).transpose(2, 0, 1), np.stack(longi).transpose(2, 0, 1)


#: relative frequency difference below which modes form one eigenspace (a repeated pair)
REPEATED_RTOL = 1e-7


def localise_repeated(freqs, shapes, M, J, scene: Scene, inst) -> np.ndarray:
    """Real shapes (n, n_modes) with the basis of every repeated eigenspace chosen by the spans.

    Any basis of a repeated eigenspace is a valid set of modes, and eigh returns an arbitrary
    one: two equal spans' transverse modes come out as mixtures of both ("a + b").  Within
    each cluster of frequencies equal to ``REPEATED_RTOL`` (M-orthonormal columns), the
    basis is rotated to the eigenvectors of the span-energy form that separates the cluster
    most (the transverse or longitudinal kinetic energy of one span, or one body's), so each
    mode is as much one span's as the eigenspace allows.  Frequencies are unchanged; numpy.
    """
    V = np.array(np.real(shapes), dtype=float)
    f = np.asarray(freqs)
    M = np.asarray(M)
    arrays = label_arrays(scene, inst)
    Jn = np.asarray(J)
    i = 0
    while i < len(f):
        j = i + 1
        while j < len(f) and f[i] >= RIGID_HZ and abs(f[j] - f[i]) <= REPEATED_RTOL * f[i]:
            j += 1
        if j - i >= 2:
            C = V[:, i:j]
            k = j - i
            pairs = [(a, b) for a in range(k) for b in range(a, k)]
            combos = np.stack([C[:, a] + C[:, b] if a != b else C[:, a] for a, b in pairs], axis=1)
            shares, _, _ = full_energy_shares(Jn @ combos, scene, arrays)
            total = np.einsum("im,ij,jm->m", combos, M, combos)
            best, R = -1.0, None
            for share in shares.values():
                E = share * total  # the energy of that span or body in each combination
                A = np.zeros((k, k))
                for (a, b), e in zip(pairs, E):
                    A[a, b] = e
                for a, b in pairs:
                    if a != b:
                        A[a, b] = A[b, a] = 0.5 * (A[a, b] - A[a, a] - A[b, b])
                w, U = np.linalg.eigh(0.5 * (A + A.T))
                if w[-1] - w[0] > best:
                    best, R = w[-1] - w[0], U
            V[:, i:j] = C @ R
        i = j
    return V


def label_modes(freqs, shapes, qi, scene: Scene, inst, J=None):
    """Labels ("1st transverse crank-alternator", "2nd rotational (alternator, crank)", "rigid body").

    Returns (labels, shares dict).  Transverse and longitudinal orders count the
    half-waves of the dominant span's profile; rotational orders count modes.
    """
    shares, trans, longi = energy_shares(shapes, qi, scene, inst, J)
    return _labels(freqs, shares, trans, longi, scene), shares


def label_full(freqs, V, scene: Scene, arrays: dict):
    """:func:`label_modes` of full-coordinate shapes V (n_full, n_modes) with :func:`label_arrays`
    (e.g. from :func:`tracking_shapes`, computed under jit): (labels, shares dict)."""
    shares, trans, longi = full_energy_shares(V, scene, arrays)
    return _labels(freqs, shares, trans, longi, scene), shares


def _labels(freqs, shares, trans, longi, scene: Scene) -> list[str]:
    names = drive.span_names(scene)
    bodies = drive.body_names(scene)
    labels, n_rot = [], 0
    for m, f in enumerate(np.asarray(freqs)):
        if f < RIGID_HZ:
            labels.append("rigid body")
            continue
        tr = np.array([shares[f"{s} transverse"][m] for s in names])
        lo = np.array([shares[f"{s} longitudinal"][m] for s in names])
        ro = np.array([shares[b][m] for b in bodies])
        kind = int(np.argmax([tr.sum(), lo.sum(), ro.sum()]))
        if kind == 2:
            n_rot += 1
            order = np.argsort(-ro)
            who = [bodies[i] for i in order if ro[i] >= NAME_SHARE * ro.sum()]
            labels.append(f"{_ordinal(n_rot)} rotational ({', '.join(who)})")
            continue
        part = tr if kind == 0 else lo
        prof = trans if kind == 0 else longi
        order = np.argsort(-part)
        who = [names[i] for i in order if part[i] >= NAME_SHARE * part.sum()]
        k = _half_waves(prof[m, order[0]])
        word = "transverse" if kind == 0 else "longitudinal"
        labels.append(f"{_ordinal(k)} {word} {' + '.join(who)}")
    return labels


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
    st = statics.analyse_statics(scene, speed, allow_supercritical=True)  # checks the scene and the speed
    v = st.speed_m_s
    gyro = effects_of(scene).moving_belt and v != 0.0
    qi = jnp.asarray(st.qi)
    out = modes_at(drive.canonical(scene), qi, st.inst, v, gyro)
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
