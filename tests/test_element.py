"""Autodiff element matrices against the thesis' closed forms (eqs. 3.9-3.40), to 1e-10 relative.

The closed forms are typed here as printed in the thesis: they are the oracle
the energies are checked against, not part of the product.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from beltjax import ancf
from beltjax.ancf import Section

RTOL = 1e-10
L = 0.0637
RHOA = 0.17685
EA = 4.725e6


def _close(a, b, rtol=RTOL):
    a, b = np.asarray(a), np.asarray(b)
    assert np.max(np.abs(a - b)) <= rtol * np.max(np.abs(b)), np.max(np.abs(a - b)) / np.max(np.abs(b))


def _expand(m4):
    """Scalar 4x4 pattern -> 8x8 matrix acting on (x, y) pairs (the thesis' layout)."""
    return np.kron(np.asarray(m4), np.eye(2))


def mass_closed(m, L):
    """Eq. (3.9)."""
    return m * _expand([
        [13 / 35, 11 * L / 210, 9 / 70, -13 * L / 420],
        [11 * L / 210, L**2 / 105, 13 * L / 420, -(L**2) / 140],
        [9 / 70, 13 * L / 420, 13 / 35, -11 * L / 210],
        [-13 * L / 420, -(L**2) / 140, -11 * L / 210, L**2 / 105],
    ])


def kt_closed(EI, L):
    """Eq. (3.27)."""
    return EI / L**3 * _expand([
        [12, 6 * L, -12, 6 * L],
        [6 * L, 4 * L**2, -6 * L, 2 * L**2],
        [-12, -6 * L, 12, -6 * L],
        [6 * L, 2 * L**2, -6 * L, 4 * L**2],
    ])


def gyro_closed(m, c, L):
    """Eq. (3.39)."""
    return m * c / L * _expand([
        [0, L / 5, 1, -L / 5],
        [-L / 5, 0, L / 5, -(L**2) / 30],
        [-1, -L / 5, 0, L / 5],
        [L / 5, L**2 / 30, -L / 5, 0],
    ])


def centrifugal_closed(m, c, L):
    """Eq. (3.40)."""
    return -m * c**2 / L**2 * _expand([
        [6 / 5, L / 10, -6 / 5, L / 10],
        [L / 10, 2 * L**2 / 15, -L / 10, -(L**2) / 30],
        [-6 / 5, -L / 10, 6 / 5, -L / 10],
        [L / 10, -(L**2) / 30, -L / 10, 2 * L**2 / 15],
    ])


def gravity_closed(m, L, g=9.81):
    """Eq. (3.13)."""
    return -m * g * np.array([0, 1 / 2, 0, L / 12, 0, 1 / 2, 0, -L / 12])


def kl_closed(e, EA, L):
    """Eqs. (3.21)-(3.23): the secant axial matrix, Q_l = K_l(e) e."""
    e1, e2, e3, e4, e5, e6, e7, e8 = e
    dx, dy = e5 - e1, e6 - e2
    ax, ay, bx, by = L * e3, L * e4, L * e7, L * e8
    d2, a2, b2 = dx * dx + dy * dy, ax * ax + ay * ay, bx * bx + by * by
    A = 3 / (70 * L**2) * (a2 + b2 - 14 * L**2 - 6 * ax * dx - 6 * bx * dx - 6 * ay * dy - 6 * by * dy + 24 * d2)
    B = 1 / (280 * L) * (b2 - a2 + 2 * ax * bx + 2 * ay * by - 14 * L**2 - 24 * ax * dx - 24 * ay * dy + 36 * d2)
    C = 1 / (280 * L) * (a2 - b2 + 2 * ax * bx + 2 * ay * by - 14 * L**2 - 24 * bx * dx - 24 * by * dy + 36 * d2)
    D = 1 / 420 * (12 * a2 + b2 - 3 * ax * bx - 3 * ay * by - 28 * L**2 + 3 * ax * dx - 3 * bx * dx
                   + 3 * ay * dy - 3 * by * dy + 18 * d2)
    E = -1 / 840 * (3 * a2 + 3 * b2 - 4 * ax * bx - 4 * ay * by - 14 * L**2 + 6 * ax * dx + 6 * bx * dx
                    + 6 * ay * dy + 6 * by * dy)
    F = 1 / 420 * (a2 + 12 * b2 - 3 * ax * bx - 3 * ay * by - 28 * L**2 - 3 * ax * dx + 3 * bx * dx
                   - 3 * ay * dy + 3 * by * dy + 18 * d2)
    return EA / L * _expand([[A, B, -A, C], [B, D, -B, E], [-A, -B, A, -C], [C, E, -C, F]])


def random_states(n=5, seed=0):
    """Element states around a stretched, rotated, bent element (m, -)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        ang = rng.uniform(-np.pi, np.pi)
        lam = 1.0 + rng.uniform(-0.05, 0.05)
        t = np.array([np.cos(ang), np.sin(ang)])
        r1 = rng.normal(size=2) * 0.1
        r2 = r1 + lam * L * t + rng.normal(size=2) * 0.003
        s1 = lam * t + rng.normal(size=2) * 0.05
        s2 = lam * t + rng.normal(size=2) * 0.05
        out.append(np.concatenate([r1, s1, r2, s2]))
    return out


def test_mass_matrix_eq_3_9():
    _close(ancf.mass_matrix(RHOA, L), mass_closed(RHOA * L, L))


def test_bending_stiffness_eq_3_27_at_any_state():
    for e in random_states():
        _close(ancf.tangent_stiffness(jnp.asarray(e), Section(0.0, 0.8859, RHOA), L), kt_closed(0.8859, L))


@pytest.mark.parametrize("c", [10.0, -3.7])
def test_gyroscopic_eq_3_39(c):
    G = ancf.gyroscopic_matrix(c, RHOA, L)
    _close(G, gyro_closed(RHOA * L, c, L))
    _close(G, -G.T)


@pytest.mark.parametrize("c", [10.0, 30.0])
def test_centrifugal_eq_3_40(c):
    _close(ancf.centrifugal_matrix(c, RHOA, L), centrifugal_closed(RHOA * L, c, L))


def test_gravity_eq_3_13():
    _close(ancf.gravity_forces(RHOA, L), gravity_closed(RHOA * L, L))


def test_axial_matrix_eq_3_21_to_3_23_at_random_states():
    for e in random_states(6, seed=1):
        e = jnp.asarray(e)
        K_closed = kl_closed(np.asarray(e), EA, L)
        _close(ancf.axial_secant_matrix(e, EA, L), K_closed)
        # the force from the energy by autodiff is K_l(e) e (eq. 3.20)
        Q = jax.grad(ancf.axial_energy)(e, EA, L)
        _close(Q, K_closed @ np.asarray(e))


def test_exact_curvature_reduces_to_linear_for_straight_unstretched_element():
    """Both bending models agree in value and Hessian at the straight, unstretched state."""
    e = jnp.array([0.0, 0.0, 1.0, 0.0, L, 0.0, 1.0, 0.0])
    s = Section(0.0, 0.8859, RHOA)
    _close(ancf.tangent_stiffness(e, s, L, "exact")[1::2, 1::2], kt_closed(0.8859, L)[1::2, 1::2], rtol=1e-9)


def test_exact_curvature_of_a_circular_arc():
    """A Hermite arc of radius R has curvature ~1/R; the exact model sees it, rigid rotation costs nothing."""
    R, th = 0.5, 0.1  # m, rad: arc of length R*th = L_arc
    Larc = R * th
    e = jnp.array([R, 0.0, 0.0, 1.0, R * np.cos(th), R * np.sin(th), -np.sin(th), np.cos(th)])
    U = ancf.bending_energy_exact(e, 1.0, Larc)
    assert abs(U - 0.5 * Larc / R**2) < 2e-3 * 0.5 * Larc / R**2
    # rigid rotation of a straight element: zero bending and axial energy in the exact model
    ang = 0.7
    t = np.array([np.cos(ang), np.sin(ang)])
    e_rot = jnp.asarray(np.concatenate([[0.0, 0.0], t, L * t, t]))
    assert abs(ancf.bending_energy_exact(e_rot, 1.0, L)) < 1e-20
    assert abs(ancf.axial_energy(e_rot, EA, L)) < 1e-12


def test_transport_acceleration_term():
    """A varying transport speed adds -rhoA dc/dt int S^T S' e dx (from d/dt of the momentum)."""
    e = jnp.asarray(random_states(1, seed=3)[0])
    z = jnp.zeros(8)
    f0 = ancf.inertial_forces(e, z, 5.0, 0.0, RHOA, L)
    f1 = ancf.inertial_forces(e, z, 5.0, 2.0, RHOA, L)
    P = jax.jacfwd(ancf.momentum, argnums=2)(e, z, 0.0, RHOA, L)  # = int rhoA S^T S' e dx
    _close(f1 - f0, -2.0 * P)
    # a straight unstretched element moving along itself at constant speed: no force on the
    # slopes, and end forces +-rhoA c^2 (the centrifugal end terms) that cancel in sum
    e_s = jnp.array([0.0, 0.0, 1.0, 0.0, L, 0.0, 1.0, 0.0])
    f = np.asarray(ancf.inertial_forces(e_s, z, 7.0, 0.0, RHOA, L))
    _close(f, RHOA * 7.0**2 * np.array([-1.0, 0, 0, 0, 1.0, 0, 0, 0]))
