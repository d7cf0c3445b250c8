"""The rotational model's reduced equations (massless bar spans), by their structure: the bodies'
Jacobian compressed by its known sparsity and the reduced mass solved as a diagonal plus a
Schur complement on the layout's coordinates.  Units: SI."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from beltjax.scene import Scene
from beltjax.drive import belt_slip
from beltjax.drive.assembly import drive_of
from beltjax.drive.effects import effects_of
from beltjax.drive.forces import bar_axial_force, body_forces
from beltjax.drive.kinematics import _body_coordinates, _centers, angles_and_arm, rotor_angles, span_lengths_and_jacobian, wraps
from beltjax.drive.topology import Installation, element_length
from beltjax.drive.equations import ReducedMass, _rim_transport_speed, _small_matmul_tn, _small_spd_solve, transport_speed


def bar_accelerations(qi, qi_dot, scene: Scene, inst: Installation, rm: ReducedMass, t=None, speed=0.0, slip=None,
                      Q=None):
    """:func:`reduced_accelerations` of the rotational model (rad/s^2), from the span lengths.

    Its spans are massless bars: their nodes carry no inertia, and their forces reach q_i
    only through the span lengths l(q_i) (:func:`span_lengths`, the same kinematic map), so
    F_ii = J_b^T (F_b - M_b gamma_b) - (dl/dq_i)^T (N + CA/L0 dl/dt) with the bodies' rows
    J_b of J and the bars' axial forces N = dV/dl (Green-Lagrange, less the centrifugal
    term: :func:`beltjax.drive.spans.bar_energy`).  Same equations as the general path to round-off
    (tests/test_fast_paths.py), about 4x cheaper on the tensioner bench: the span nodes'
    coordinates and their derivatives are never formed.  With slip states ``slip`` (m,
    :mod:`beltjax.drive.belt_slip`) the spans' lengths carry the slip's share and the slip
    rates (m/s) are returned beside q_i''.
    """
    steady = t is None
    tt = jnp.zeros((), dtype=qi.dtype) if steady else jnp.asarray(t, dtype=qi.dtype)
    one = jnp.zeros_like(tt) if steady else jnp.ones_like(tt)

    def bodies(x, time):
        phi, theta = angles_and_arm(x, scene, inst)
        centers, _ = _centers(theta, scene, inst)
        return _body_coordinates(phi, theta, centers, scene, inst, None if steady else time, rotors=rotor_angles(x, scene))

    b, b_dot = jax.jvp(bodies, (qi, tt), (qi_dot, one))
    _, gamma_b = jax.jvp(lambda x, time: jax.jvp(bodies, (x, time), (qi_dot, one))[1], (qi, tt), (qi_dot, one))
    J_b = bodies_jacobian(lambda x: bodies(x, tt), qi, scene)
    l, J_l = span_lengths_and_jacobian(qi, scene, inst)
    n = len(scene.route.order)
    if slip is not None:
        l = l + belt_slip.length_offsets(slip, n)
    B, B_dot = b.reshape(-1, 3), b_dot.reshape(-1, 3)
    if steady:
        c = transport_speed(scene, inst, speed)
    else:  # the drive pulley's actual rim speed, as transient_transport_speed
        c = _rim_transport_speed(scene, inst, B_dot)
    L0 = element_length(scene, inst)
    fx = effects_of(scene)
    cc = fx.transport_speed(c)
    rate = jnp.sum(J_l * qi_dot, axis=1) if not steady and "belt_damping" in fx else None
    z_dot = None
    if slip is not None:  # the friction law sees the spans' elastic forces
        N_el = jax.vmap(lambda l_, L0_: bar_axial_force(l_, None, L0_, scene, cc))(l, L0)
        rims = jnp.asarray(scene.route.senses, dtype=qi.dtype) * inst.radii * B_dot[:n, 2]
        z_dot = belt_slip.rates(N_el, l / L0, rims, scene, inst, wraps(qi, scene, inst), slip)
        if rate is not None:  # the belt's damping acts on its whole stretching rate, slip included
            rate = rate + belt_slip.length_offsets(z_dot, n)
    N = jax.vmap(lambda l_, r_, L0_: bar_axial_force(l_, r_, L0_, scene, cc),
                 in_axes=(0, None if rate is None else 0, 0))(l, rate, L0)
    F_b = body_forces(B, scene, inst, None if steady else B_dot, None if steady else tt).reshape(-1)
    F_i = J_b.transpose_times(F_b - rm.m_body * gamma_b) - _small_matmul_tn(J_l, N)
    if Q is not None:  # generalised forces from outside (the pivot's friction: reduced_accelerations)
        F_i = F_i + Q
    acc = _rigid_solve(J_b, rm.m_body, F_i)
    return acc if slip is None else (acc, z_dot)


class BodiesJacobian(NamedTuple):
    """The rotational model's bodies' Jacobian d b / d q_i in compressed form (:func:`bodies_jacobian`).

    own: the body each own coordinate turns (:attr:`beltjax.drive.assembly.Drive.own_bodies`);
    c (n_body_coordinates,): the sum of the own coordinates' columns (no two share a row);
    J_B (n_body_coordinates, k): the layout's coordinates' columns (the last k of q_i).
    """

    own: tuple
    c: jax.Array
    J_B: jax.Array

    def own_sum(self, x):
        """P^T x for the own columns' 0/1 pattern P: x (n_body_coordinates, ...) summed over each
        own coordinate's body rows -> (n_own, ...)."""
        return x.reshape((-1, 3) + x.shape[1:]).sum(axis=1)[np.asarray(self.own, dtype=int)]

    def transpose_times(self, x):
        """J_b^T x (n_i,) for x (n_body_coordinates,)."""
        return jnp.concatenate([self.own_sum(self.c * x), _small_matmul_tn(self.J_B, x)])

    def dense(self):
        """J_b (n_body_coordinates, n_i)."""
        P = np.zeros((self.c.shape[0], len(self.own)))
        for j, b in enumerate(self.own):
            P[3 * b : 3 * b + 3, j] = 1.0
        return jnp.concatenate([self.c[:, None] * P, self.J_B], axis=1)


def bodies_jacobian(bodies, qi, scene: Scene) -> BodiesJacobian:
    """d bodies / d q_i of the rotational model, ``bodies(q_i)`` its body coordinates (m, rad), by
    1 + k forward passes instead of n_i (k: the layout's coordinates).

    The own coordinates (:attr:`beltjax.drive.assembly.Drive.own_bodies`) each move their own
    body only, so their columns share no row (Curtis-Powell-Reid): one pass along their sum
    holds them all, and the known pattern gives each row its column.  The layout's coordinates
    take a pass each.
    """
    own = drive_of(scene).own_bodies
    a, nq = len(own), qi.shape[0]
    T = np.zeros((1 + nq - a, nq))
    T[0, :a] = 1.0
    T[1 + np.arange(nq - a), a + np.arange(nq - a)] = 1.0
    C = jax.vmap(lambda v: jax.jvp(bodies, (qi,), (v,))[1])(jnp.asarray(T, dtype=qi.dtype))
    return BodiesJacobian(own, C[0], C[1:].T)


def _rigid_solve(Jb: BodiesJacobian, m, F):
    """q_i'' = M_ii^-1 F (rad/s^2) for the rotational model's M_ii = J_b^T diag(m) J_b, by its structure.

    Jb: the bodies' Jacobian (:func:`bodies_jacobian`); m: the bodies' masses and inertias (kg,
    kg m^2); F (n_i,): the generalised forces (N m).  No two own coordinates' columns share a
    row, so their block of M_ii is diagonal, D; the solve is by the Schur complement on the
    layout's k coordinates, S = M_BB - M_AB^T D^-1 M_AB (k x k), elementwise elsewhere: a
    handful of fused kernels where an unrolled elimination of the whole M_ii took two per unknown
    (the vector field is evaluated tens of thousands of times per simulated second).  Same
    result to round-off (tests/test_fast_paths.py against the dense solve of
    :func:`reduced_system`).
    """
    a = len(Jb.own)
    D = Jb.own_sum(m * Jb.c**2)
    F_A, F_B = F[:a], F[a:]
    if Jb.J_B.shape[1] == 0:
        return F_A / D
    mJ_B = m[:, None] * Jb.J_B
    M_AB = Jb.own_sum(Jb.c[:, None] * mJ_B)  # (a, k)
    X = M_AB / D[:, None]
    S = _small_matmul_tn(Jb.J_B, mJ_B) - _small_matmul_tn(M_AB, X)
    a_B = _small_spd_solve(S, F_B - _small_matmul_tn(X, F_A))
    return jnp.concatenate([(F_A - jnp.sum(M_AB * a_B[None, :], axis=1)) / D, a_B])


_bar_accelerations = bar_accelerations  # the name tests and benchmarks used
