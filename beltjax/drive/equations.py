"""Reduced equations M_ii = J^T M J, F_ii = J^T (F - M gamma): full motion, the reduced mass,
accelerations (the dense solve and the rotational model's fast path), transport speed and travel
inertia, and the static residual.  Units: SI."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from beltjax import ancf, span
from beltjax.scene import Scene
from beltjax.drive.topology import Installation, drive_pulley, element_length, n_rigid, n_span_coordinates, travel_coordinate, travel_follows_drive
from beltjax.drive.spans import spans_of
from beltjax.drive.effects import effects_of
from beltjax.drive.kinematics import belt_travel, full_coordinates, split_full
from beltjax.drive.forces import full_forces, full_mass_matrix, mean_body_loads, span_mass_blocks


def transport_speed(scene: Scene, inst: Installation, speed):
    """Transport speed c (m of unstretched belt per s) for a belt speed ``speed`` (m/s)."""
    return speed / inst.stretch


def full_motion(qi, qi_dot, scene: Scene, inst: Installation, speed=0.0, t=None, rigid_only=False, slip=None,
                slip_rate=None):
    """Full coordinates and what the reduced equations need of them, at (q_i, q_i', t).

    Returns (q, v, gamma, J, F): q = Phi(q_i, t) and its rate v; gamma = d(J q_i')/dt at
    q_i'' = 0 (with the time terms of Phi); J = dPhi/dq_i; the forces F of
    :func:`full_forces`.  speed: belt speed (m/s) when ``t`` is None (steady motion, the
    map without time); with a time t (s) the belt speed and its rate follow
    :func:`belt_travel` and the damping effects and loads act.  rigid_only: J holds only
    the columns of the rigid coordinates, ``J[:, :n_rigid]`` (the span columns are the
    constant selection of :func:`span_coordinate_index`).  slip, slip_rate: the belt's slip
    states (m) and their rates (m/s) (:mod:`beltjax.drive.belt_slip`, a transient's): the span
    nodes' rates carry the slip's (the belt's damping sees them; they reach no inertia).
    """
    if rigid_only:
        nr = n_rigid(scene)
        q, v, gamma, _, F = _full_motion(qi, qi_dot, scene, inst, speed, t, skip_jacobian=True, slip=slip,
                                         slip_rate=slip_rate)
        steady = t is None
        tt = jnp.zeros((), dtype=qi.dtype) if steady else jnp.asarray(t, dtype=qi.dtype)
        rest = qi[nr:]

        def phi_r(xr):
            return full_coordinates(jnp.concatenate([xr, rest]), scene, inst, t=None if steady else tt, slip=slip)

        return q, v, gamma, jax.jacfwd(phi_r)(qi[:nr]), F
    return _full_motion(qi, qi_dot, scene, inst, speed, t, slip=slip, slip_rate=slip_rate)


def _full_motion(qi, qi_dot, scene: Scene, inst: Installation, speed=0.0, t=None, skip_jacobian=False, slip=None,
                 slip_rate=None):
    steady = t is None
    t = jnp.zeros((), dtype=qi.dtype) if steady else jnp.asarray(t, dtype=qi.dtype)
    one = jnp.zeros_like(t) if steady else jnp.ones_like(t)  # the time's tangent
    t0 = t

    def phi(x, tt):
        z = slip if slip is None or slip_rate is None else slip + (tt - t0) * slip_rate
        return full_coordinates(x, scene, inst, t=None if steady else tt, slip=z)

    rate = lambda x, tt: jax.jvp(phi, (x, tt), (qi_dot, one))[1]  # noqa: E731
    q, v = jax.jvp(phi, (qi, t), (qi_dot, one))
    if spans_of(scene).massive:
        _, gamma = jax.jvp(rate, (qi, t), (qi_dot, one))
    else:
        # massless spans (bars): their end nodes' accelerations carry no inertia, so only the
        # bodies' convective accelerations are formed (the span part would be multiplied by zero
        # mass; with a tensioner it is the second derivative of the tangent geometry)
        ns = n_span_coordinates(scene)
        body_rate = lambda x, tt: rate(x, tt)[ns:]  # noqa: E731
        _, gamma_b = jax.jvp(body_rate, (qi, t), (qi_dot, one))
        gamma = jnp.concatenate([jnp.zeros(ns, dtype=q.dtype), gamma_b])
    J = None if skip_jacobian else jax.jacfwd(phi)(qi, t)
    if steady:
        F = full_forces(q, v, scene, inst, transport_speed(scene, inst, speed))
    else:
        c, c_dot = transient_transport_speed(scene, inst, v, t)
        F = full_forces(q, v, scene, inst, c, c_dot, t=t)
    return q, v, gamma, J, F


def reduced_system(qi, qi_dot, scene: Scene, inst: Installation, speed=0.0, M_full=None, t=None):
    """Reduced mass matrix and forces: ``M_ii = J^T M J``, ``F_ii = J^T (F - M gamma)``.

    qi, qi_dot: independent coordinates and rates; speed: belt speed (m/s) when ``t`` is
    None (steady motion).  t: time (s) of a transient: the map is then Phi(q_i, t), the
    belt speed and its rate follow :func:`belt_travel`, and the damping effects and loads
    act.  Returns (M_ii, F_ii) in kg / kg m^2 and N / N m.  The pivot's dry friction is not in
    F_ii: it depends on the accelerations and acts through :func:`reduced_accelerations`.
    """
    M = full_mass_matrix(scene, inst) if M_full is None else M_full
    q, v, gamma, J, F = full_motion(qi, qi_dot, scene, inst, speed, t)
    return with_travel_inertia(J.T @ M @ J, J.T @ (F - M @ gamma), J, travel_inertia(q, v, gamma, scene, inst, t))


def span_coordinate_index(scene: Scene) -> np.ndarray:
    """Position in the full vector q of each span coordinate of q_i (q_i order after the rigid ones).

    :func:`full_coordinates` copies the span coordinates of q_i (end slopes, interior nodes)
    into q unchanged, so ``dPhi/dq_i`` is, on these columns, the constant selection
    ``J[idx[k], n_rigid + k] = 1`` (zero elsewhere), whatever q_i and t.  Empty for the
    rotational model (the span component's, :func:`beltjax.drive.spans.spans_of`).
    """
    return spans_of(scene).coordinate_index(len(scene.route.order))


class ReducedMass(NamedTuple):
    """What the structured solve of :func:`reduced_accelerations` keeps of a drive (per run).

    M_full: full mass matrix (block diagonal: the spans' blocks, then the bodies' diagonal);
    blocks: the spans' blocks (n spans, 4 (N+1), 4 (N+1)) (:func:`span_mass_blocks`); inv_ss:
    the inverse of each span's block on its independent coordinates, (n, 4 N, 4 N), so that
    M_ss^-1 is a batched product (None without span coordinates); m_body: the diagonal of the
    bodies' block (:func:`body_masses`, kg, kg m^2); BC: the spans' transport matrices when the
    belt's travel follows a free drive pulley (:func:`span_transport_matrices`), else None.
    """

    M_full: jax.Array
    blocks: jax.Array | None
    inv_ss: jax.Array | None
    m_body: jax.Array
    BC: tuple | None = None


def reduced_mass(scene: Scene, inst: Installation, M_full=None) -> ReducedMass:
    """The constant parts of M_ii = J^T M J for :func:`reduced_accelerations` (factor once per run)."""
    M = full_mass_matrix(scene, inst) if M_full is None else M_full
    ns = n_span_coordinates(scene)
    m_body = jnp.diagonal(M)[ns:]
    if span_coordinate_index(scene).size == 0:
        return ReducedMass(M, None, None, m_body)
    loc = _span_local_index(scene)
    blocks = span_mass_blocks(scene, inst)  # the blocks M_full is made of (:func:`full_mass_matrix`)
    M_ss = blocks[:, loc][:, :, loc]
    eye = jnp.broadcast_to(jnp.eye(loc.size, dtype=M.dtype), M_ss.shape)
    inv_ss = jax.vmap(lambda A, I: jax.scipy.linalg.cho_solve((jnp.linalg.cholesky(A), True), I))(M_ss, eye)
    BC = span_transport_matrices(scene, inst) if travel_follows_drive(scene) else None
    return ReducedMass(M, blocks, inv_ss, m_body, BC)


def _span_local_index(scene: Scene) -> np.ndarray:
    """Position of each independent span coordinate within its span's full coordinates."""
    return spans_of(scene).coordinate_index(1)


def _block_product(rm: ReducedMass, x):
    """M_full @ x by its blocks (x: (n_full,) or (n_full, m)): the spans' blocks batched, the
    bodies' diagonal."""
    n, P = rm.blocks.shape[0], rm.blocks.shape[1]
    ns = n * P
    xs = x[:ns].reshape((n, P) + x.shape[1:])
    spans = jnp.einsum("spq,sq...->sp...", rm.blocks, xs).reshape((ns,) + x.shape[1:])
    body = rm.m_body.reshape((-1,) + (1,) * (x.ndim - 1)) * x[ns:]
    return jnp.concatenate([spans, body])


def _small_matmul_tn(A, B):
    """A^T @ B for a tall A (n, k) and B (n,) or (n, m) with small k, m, as a fused multiply and
    sum (no dot call)."""
    if B.ndim == 1:
        return jnp.sum(A * B[:, None], axis=0)
    return jnp.sum(A[:, :, None] * B[:, None, :], axis=0)


def reduced_accelerations(qi, qi_dot, scene: Scene, inst: Installation, rm: ReducedMass, t=None, speed=0.0,
                          slip=None):
    """q_i'' = M_ii^-1 F_ii of :func:`reduced_system`, by the block structure of J (rad/s^2, m/s^2).

    J = [J_r | S]: the rigid columns J_r (autodiff, n_rigid tangents) and the constant
    selection S of the span coordinates (:func:`span_coordinate_index`).  Hence
    M_ii = [[J_r^T M J_r, J_r^T M S], [S^T M J_r, M_ss]] with the constant span block
    M_ss factored once (``rm``, :func:`reduced_mass`), F_ii = [J_r^T r, r[idx]] with
    r = F - M gamma, and the solve is by the Schur complement on the rigid coordinates:
    O(n^2) per call instead of forming J^T M J (O(n_full^2 n)) and an LU (O(n^3)).  Same
    equations as ``jnp.linalg.solve(*reduced_system(...))`` to round-off.  The rotational
    model (massless bars) goes by the span lengths instead:
    :func:`beltjax.drive.rotational.bar_accelerations`.  The span
    component chooses (:meth:`beltjax.drive.spans.SpanModel.accelerations`).  With slip states
    ``slip`` (m, effect ``belt_slip``: :mod:`beltjax.drive.belt_slip`) it returns
    (q_i'', the slip rates m/s).  The listed effects that depend on the accelerations (the
    pivot's dry friction) act here, on the span component's accelerations under added
    generalised forces (:meth:`beltjax.drive.effects.Effects.accelerations`).
    """
    spans = spans_of(scene)
    return effects_of(scene).accelerations(
        lambda Q: spans.accelerations(qi, qi_dot, scene, inst, rm, t, speed, slip, Q), qi, qi_dot, scene, inst, t)


def schur_accelerations(qi, qi_dot, scene: Scene, inst: Installation, rm: ReducedMass, t=None, speed=0.0, Q=None):
    """:func:`reduced_accelerations` of a drive with massive (ANCF) spans, by the Schur complement
    (every such span has span coordinates: at least one element of 4 N independent ones)."""
    nr = n_rigid(scene)
    idx = span_coordinate_index(scene)
    q, v, gamma, J_r, F = full_motion(qi, qi_dot, scene, inst, speed, t, rigid_only=True)
    # M is block diagonal: its products and the span block's inverse go by blocks
    r = F - _block_product(rm, gamma)
    MJ = _block_product(rm, J_r)
    M_rr, F_r = J_r.T @ MJ, J_r.T @ r
    # a free drive pulley's travel: its coupling reaches only the rigid rows (k < n_rigid) and
    # the span rows' column k (S^T P = P[idx]); the span block M_ss stays constant
    ti = travel_inertia(q, v, gamma, scene, inst, t, rm.BC)
    M_rr, F_r = with_travel_inertia(M_rr, F_r, J_r, ti)
    F_s = r[idx]
    if Q is not None:  # generalised forces from outside (the pivot's friction: reduced_accelerations)
        F_r, F_s = F_r + Q[:nr], F_s + Q[nr:]
    M_sr = MJ[idx]  # (n_span, n_rigid)
    if ti is not None:
        M_sr = M_sr.at[:, ti.k].add(ti.kappa * ti.P[idx])
    n, k = rm.inv_ss.shape[0], rm.inv_ss.shape[1]
    rhs = jnp.concatenate([M_sr, F_s[:, None]], axis=1).reshape(n, k, nr + 1)
    X = jnp.einsum("sij,sjm->sim", rm.inv_ss, rhs).reshape(n * k, nr + 1)
    if nr == 0:
        return X[:, 0]
    S_c = M_rr - M_sr.T @ X[:, :nr]
    b = F_r - M_sr.T @ X[:, nr]
    a_r = _small_spd_solve(S_c, b)
    return jnp.concatenate([a_r, X[:, nr] - X[:, :nr] @ a_r])


#: largest rigid block solved by the unrolled Gauss-Jordan elimination of :func:`_small_spd_solve`
UNROLLED_SOLVE_MAX = 8


def _small_spd_solve(A, b):
    """A^-1 b for a small symmetric positive definite A (a mass matrix of the rigid coordinates).

    Up to :data:`UNROLLED_SOLVE_MAX` unknowns by Gauss-Jordan elimination unrolled over the
    columns, each a whole-array update that XLA fuses (no pivoting: A is SPD, for which
    elimination without pivoting is stable).  The LAPACK calls of ``jnp.linalg.solve`` cost
    more in fixed overhead than the arithmetic at these sizes, and so does a scalar-unrolled
    Cholesky (a rotational drive's vector field is a microsecond or two, evaluated tens of
    thousands of times per simulated second).
    """
    n = A.shape[0]
    if n > UNROLLED_SOLVE_MAX:
        return jnp.linalg.solve(A, b)
    M = jnp.concatenate([A, b[:, None]], axis=1)
    rows = jnp.arange(n)[:, None]
    for k in range(n):
        pivot = M[k] / M[k, k]
        M = jnp.where(rows == k, pivot[None, :], M - M[:, k : k + 1] * pivot[None, :])
    return M[:, n]


def transient_transport_speed(scene: Scene, inst: Installation, v, t):
    """Transport speed c (m/s of unstretched belt) and the known part of its rate c_0' (m/s^2)
    at time t (s) of a transient, full coordinate rates v.

    c is the drive pulley's actual rim speed, c = s R theta' / lam (the thesis' c = R theta'),
    in both fidelities: the nominal travel's rate (:func:`belt_travel`) for a driven drive
    pulley, and for a free one (:func:`travel_follows_drive`) what its torque and the belt make
    of it, so that the centrifugal tension follows a crank turned by a torque.  c_0' is the
    nominal travel's acceleration / lam; a free drive pulley's own share, kappa phi_d''
    (:func:`travel_inertia`), belongs to the mass matrix of the hybrid model.
    """
    _, _, xdd = _travel_rates(scene, t)
    _, Bd = split_full(v, scene)
    return _rim_transport_speed(scene, inst, Bd), xdd / inst.stretch


def _travel_gain(scene: Scene, inst: Installation):
    """kappa = s R / lam (m/rad): the drive pulley's rim travel per radian, in unstretched belt."""
    d = drive_pulley(scene)
    return scene.route.senses[d] * inst.radii[d] / inst.stretch


def _rim_transport_speed(scene: Scene, inst: Installation, bodies_dot):
    """c = s R theta' / lam (m/s of unstretched belt) of the drive pulley; bodies_dot (nb, 3)."""
    return _travel_gain(scene, inst) * bodies_dot[drive_pulley(scene), 2]


class TravelInertia(NamedTuple):
    """The belt's travel as a degree of freedom (:func:`travel_inertia`).

    k: position of the free drive pulley's angle in q_i; kappa = s R / lam (m/rad): dc/d phi_d';
    pi_c = dT/dc (N s) is the spans' momentum conjugate to the transport speed; P = d pi_c / dq'
    (kg, full vector, zero on the bodies); pi_cc = d pi_c / dc (kg, the spans' belt mass times
    lam^2); h: the rate of pi_c at q_i'' = 0 (N).
    """

    k: int
    kappa: jax.Array
    P: jax.Array
    pi_cc: jax.Array
    h: jax.Array


def span_transport_matrices(scene: Scene, inst: Installation):
    """B = rhoA int N^T N' dx (kg/m times m over m: kg) and C = rhoA int N'^T N' dx (kg) of
    every span, each (n, 4 (N+1), 4 (N+1)): the spans' kinetic energy is
    1/2 e'^T M e' + c e'^T B e + 1/2 c^2 e^T C e (ancf.kinetic_energy), so its momentum
    conjugate to the transport speed is pi_c = e'^T B e + c e^T C e."""
    N = spans_of(scene).elements
    idx = span.element_index(N)
    m = 4 * (N + 1)
    z = jnp.zeros(8)

    def one(L):
        Be = jax.jacfwd(ancf.momentum, argnums=0)(z, z, 1.0, scene.belt.rhoA, L)
        Ce = -ancf.centrifugal_matrix(1.0, scene.belt.rhoA, L)
        rows, cols = idx[:, :, None], idx[:, None, :]
        B = jnp.zeros((m, m)).at[rows, cols].add(jnp.broadcast_to(Be, (N, 8, 8)))
        C = jnp.zeros((m, m)).at[rows, cols].add(jnp.broadcast_to(Ce, (N, 8, 8)))
        return B, C

    return jax.vmap(one)(element_length(scene, inst))


def travel_inertia(q, v, gamma, scene: Scene, inst: Installation, t, BC=None) -> TravelInertia | None:
    """Inertia of the belt's travel when it follows a free drive pulley (hybrid transients).

    With c = c_0(t) + kappa phi_d' (:func:`transient_transport_speed`), the spans' kinetic
    energy T = sum 1/2 int rhoA |r_t + c r_x|^2 dx depends on phi_d' through c, so Lagrange's
    equations gain, besides the forces at this c: the rhoA dc/dt term's share kappa phi_d''
    (-P kappa phi_d'' on the span coordinates: mass coupling J^T P kappa e_k^T), and in the
    row of phi_d the rate of the momentum kappa pi_c, kappa (P . q'' + pi_cc c' + d pi_c/dq . q'),
    whose acceleration terms are the symmetric coupling and kappa^2 pi_cc (the spans' belt
    mass moving with the crank).  With pi_c = e'^T B e + c e^T C e
    (:func:`span_transport_matrices`, or ``BC`` precomputed): P = B e, pi_cc = e^T C e and
    h = gamma^T B e + e'^T B e' + 2 c e'^T C e + c_0' e^T C e.  None when the travel is
    prescribed (driven drive pulley, statics, modes) or the spans are massless (rotational
    model: there c alone follows).
    """
    if t is None or not spans_of(scene).massive or not travel_follows_drive(scene):
        return None
    n = len(scene.route.order)
    ns = n_span_coordinates(scene)
    B, C = span_transport_matrices(scene, inst) if BC is None else BC
    c, c0_dot = transient_transport_speed(scene, inst, v, t)
    e, ed, g = (x[:ns].reshape(n, -1) for x in (q, v, gamma))
    Be = jnp.einsum("sij,sj->si", B, e)
    Ce = jnp.einsum("sij,sj->si", C, e)
    pi_cc = jnp.sum(e * Ce)
    h = jnp.sum(g * Be) + jnp.sum(ed * jnp.einsum("sij,sj->si", B, ed)) + 2 * c * jnp.sum(ed * Ce) + c0_dot * pi_cc
    kappa = _travel_gain(scene, inst)
    P_full = jnp.concatenate([Be.reshape(-1), jnp.zeros(q.shape[0] - ns, dtype=q.dtype)])
    return TravelInertia(travel_coordinate(scene), kappa, P_full, pi_cc, h)


def with_travel_inertia(M_ii, F_ii, J, ti: TravelInertia | None):
    """M_ii, F_ii of the reduced equations with the travel's inertia (:func:`travel_inertia`);
    J: dPhi/dq_i (n_full, n_i)."""
    if ti is None:
        return M_ii, F_ii
    a = J.T @ ti.P
    e = jnp.zeros_like(a).at[ti.k].set(1.0)
    M_ii = M_ii + ti.kappa * (jnp.outer(a, e) + jnp.outer(e, a)) + ti.kappa**2 * ti.pi_cc * jnp.outer(e, e)
    return M_ii, F_ii - ti.kappa * ti.h * e


def _travel_rates(scene: Scene, t):
    """Belt travel (m), speed (m/s) and acceleration (m/s^2) at time t (autodiff of belt_travel)."""
    f = lambda tt: belt_travel(scene, tt)  # noqa: E731
    d1 = lambda tt: jax.jvp(f, (tt,), (jnp.ones_like(tt),))[1]  # noqa: E731
    x, v = jax.jvp(f, (t,), (jnp.ones_like(t),))
    _, a = jax.jvp(d1, (t,), (jnp.ones_like(t),))
    return x, v, a


def steady_forces(q, scene: Scene, inst: Installation, speed=0.0, loaded: bool = False):
    """Forces on the full coordinates (N, N m) in the steady motion at belt speed ``speed`` (m/s):
    the conservative ones of :func:`full_forces`, and with ``loaded`` the operating point's mean
    loads (:func:`beltjax.drive.forces.mean_body_loads`).  loaded: a bool, or a traced weight
    (1.0 or 0.0) on those loads, so that one compiled statics serves both states."""
    F = full_forces(q, jnp.zeros_like(q), scene, inst, transport_speed(scene, inst, speed))
    if loaded is not False:
        F = F.at[n_span_coordinates(scene):].add(loaded * mean_body_loads(scene, inst, speed).reshape(-1))
    return F


def static_residual(qi, scene: Scene, inst: Installation, speed=0.0, loaded: bool = False):
    """Static (steady-motion) residual F_ii(q_i, 0) (N, N m); zero at equilibrium.  With
    ``loaded`` the mean loads act (the operating point), else none (the unloaded state)."""
    phi = lambda x: full_coordinates(x, scene, inst)  # noqa: E731
    q, vjp = jax.vjp(phi, qi)
    return vjp(steady_forces(q, scene, inst, speed, loaded))[0]


def drive_torque(qi, scene: Scene, inst: Installation, speed=0.0, loaded: bool = False):
    """Torque (N m, CCW positive) that the drive pulley's shaft applies in the steady motion at
    belt speed ``speed`` (m/s): minus the generalised force of the belt (and, with ``loaded``,
    of the pulley's own mean loads) on the drive pulley's angle, which statics holds."""
    d = drive_pulley(scene)
    n = len(scene.route.order)
    t_qi, t_drv = jnp.zeros_like(qi), jnp.zeros(n, dtype=qi.dtype)
    if travel_follows_drive(scene):  # a free drive pulley: its angle is a coordinate of q_i
        t_qi = t_qi.at[travel_coordinate(scene)].set(1.0)
    else:
        t_drv = t_drv.at[d].set(1.0)
    q, dq = jax.jvp(lambda x, a: full_coordinates(x, scene, inst, driven_angle=a), (qi, jnp.zeros(n, dtype=qi.dtype)),
                    (t_qi, t_drv))
    return -(dq @ steady_forces(q, scene, inst, speed, loaded))

