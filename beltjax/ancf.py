"""The planar ANCF beam element (Berzeri & Shabana), written as energies.

Element coordinates ``e`` (8,), in this order (thesis eq. 3.4-3.6)::

    [x1, y1, x1', y1', x2, y2, x2', y2']

node positions (m) and slope vectors (dimensionless, d r / d x) at the two
ends.  ``x`` is the *reference* (unstretched) arc-length coordinate of the
element, ``L`` its reference length (m); ``rhoA`` is mass per unit
unstretched length (kg/m).  The transport speed ``c`` of an axially moving
(Eulerian / ALE) element is the rate at which unstretched belt length flows
through the element (m/s); a span at stretch ``lam`` carrying material at a
spatial speed ``v`` has ``c = v / lam``.

Every quantity below is a pure function of ``(e, e_dot, c, ...)`` that can be
``jit``-ed and ``vmap``-ed over elements; forces and matrices come from these
energies by automatic differentiation (``jax.grad`` / ``jax.hessian``), never
from hand-typed matrices.  Integrals use 5-point Gauss-Legendre quadrature,
exact for polynomials up to degree 9: exact for the mass, gyroscopic,
centrifugal, gravity and small-strain bending terms and for the Green-Lagrange
axial energy (degree 8); the exact-curvature bending energy is rational and
integrated approximately.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

GAUSS_POINTS = 5
_xg, _wg = np.polynomial.legendre.leggauss(GAUSS_POINTS)
#: Gauss abscissae on [0, 1] and their weights (sum to 1); numpy, so that importing beltjax does
#: not start a JAX backend (the process set-up, beltjax.runtime, must come first)
XI = 0.5 * (_xg + 1.0)
WEIGHTS = 0.5 * _wg

BENDING_MODELS = ("linear", "exact")


class Section(NamedTuple):
    """Cross-section properties of the belt (a pytree: gradients reach every field).

    EA: axial stiffness (N); EI: bending stiffness (N m^2);
    rhoA: mass per unit unstretched length (kg/m).
    """

    EA: jax.Array | float
    EI: jax.Array | float
    rhoA: jax.Array | float


def shape_functions(xi, L):
    """Cubic Hermite shape functions s1..s4 at xi = x/L in [0, 1] (eq. 3.3); shape (4,)."""
    return jnp.stack(
        [
            1.0 - 3.0 * xi**2 + 2.0 * xi**3,
            L * (xi - 2.0 * xi**2 + xi**3),
            3.0 * xi**2 - 2.0 * xi**3,
            L * (xi**3 - xi**2),
        ]
    )


def shape_derivative(xi, L):
    """d s_k / d x at xi (1/m for the position functions, 1 for the slope ones); shape (4,)."""
    return jnp.stack(
        [
            (-6.0 * xi + 6.0 * xi**2) / L,
            1.0 - 4.0 * xi + 3.0 * xi**2,
            (6.0 * xi - 6.0 * xi**2) / L,
            3.0 * xi**2 - 2.0 * xi,
        ]
    )


def shape_second_derivative(xi, L):
    """d^2 s_k / d x^2 at xi (1/m^2 and 1/m); shape (4,)."""
    return jnp.stack(
        [
            (-6.0 + 12.0 * xi) / L**2,
            (-4.0 + 6.0 * xi) / L,
            (6.0 - 12.0 * xi) / L**2,
            (6.0 * xi - 2.0) / L,
        ]
    )


def _nodal(e):
    """Element coordinates as a (4, 2) array: rows r1, r1', r2, r2'."""
    return jnp.reshape(e, (4, 2))


def position(e, xi, L):
    """Position r(xi) of the element's centre line (m), shape (2,)."""
    return shape_functions(xi, L) @ _nodal(e)


def slope(e, xi, L):
    """Slope r'(xi) = d r / d x (dimensionless), shape (2,)."""
    return shape_derivative(xi, L) @ _nodal(e)


def _integrate(f, L):
    """Integral over the element of f(xi) (vectorised over the Gauss points)."""
    return L * jnp.sum(WEIGHTS * jax.vmap(f)(XI))


# --------------------------------------------------------------------------- energies


def kinetic_energy(e, e_dot, c, rhoA, L):
    """Kinetic energy (J) of an axially moving element, 1/2 int rhoA |r_t + c r_x|^2 dx.

    e, e_dot: coordinates (m, -) and their rates (m/s, 1/s), shape (8,);
    c: transport speed (m/s of unstretched length); rhoA (kg/m); L (m).
    With c = 0 this is the classical 1/2 e_dot^T M e_dot (eq. 3.7).
    """

    def density(xi):
        v = position(e_dot, xi, L) + c * slope(e, xi, L)
        return 0.5 * rhoA * (v @ v)

    return _integrate(density, L)


def axial_force(lam, EA):
    """Axial force (N) of a belt at uniform stretch ``lam`` (-): EA (lam^2 - 1)/2 * lam, the
    Green-Lagrange energy's force per stretched length (the one axial-force law of beltjax)."""
    return 0.5 * EA * (lam**2 - 1.0) * lam


def axial_force_slope(lam, EA):
    """d(axial_force)/d(lam) (N): EA (3 lam^2 - 1)/2."""
    return 0.5 * EA * (3.0 * lam**2 - 1.0)


def axial_strain(e, xi, L):
    """Green-Lagrange axial strain (r'.r' - 1)/2 at xi (eq. 3.18), dimensionless."""
    rp = slope(e, xi, L)
    return 0.5 * (rp @ rp - 1.0)


def axial_energy(e, EA, L):
    """Axial strain energy 1/2 int EA eps^2 dx (J) with the Green-Lagrange strain (eq. 3.19)."""
    return _integrate(lambda xi: 0.5 * EA * axial_strain(e, xi, L) ** 2, L)


def bending_energy_linear(e, EI, L):
    """Small-strain bending energy 1/2 int EI |r''|^2 dx (J); its Hessian is K_t (eq. 3.27)."""

    def density(xi):
        rpp = shape_second_derivative(xi, L) @ _nodal(e)
        return 0.5 * EI * (rpp @ rpp)

    return _integrate(density, L)


def bending_energy_exact(e, EI, L):
    """Bending energy 1/2 int EI kappa^2 dx (J) with kappa = |r' x r''| / |r'|^3 (eq. 3.24)."""

    def density(xi):
        E = _nodal(e)
        rp = shape_derivative(xi, L) @ E
        rpp = shape_second_derivative(xi, L) @ E
        cross = rp[0] * rpp[1] - rp[1] * rpp[0]
        return 0.5 * EI * cross**2 / (rp @ rp) ** 3

    return _integrate(density, L)


def bending_energy(e, EI, L, model="linear"):
    """Bending energy (J); model "linear" (thesis' constant K_t) or "exact" curvature."""
    if model == "linear":
        return bending_energy_linear(e, EI, L)
    if model == "exact":
        return bending_energy_exact(e, EI, L)
    raise ValueError(f"bending model must be one of {BENDING_MODELS}, got {model!r}")


def gravity_energy(e, rhoA, L, g=(0.0, -9.81)):
    """Gravitational potential -int rhoA g.r dx (J); g is the acceleration vector (m/s^2)."""
    gv = jnp.asarray(g)
    return _integrate(lambda xi: -rhoA * (gv @ position(e, xi, L)), L)


def strain_energy(e, section: Section, L, bending="linear"):
    """Total elastic energy of one element (J): axial plus bending."""
    return axial_energy(e, section.EA, L) + bending_energy(e, section.EI, L, bending)


# --------------------------------------------------------------------------- forces


def momentum(e, e_dot, c, rhoA, L):
    """Generalised momentum dT/d e_dot (kg m/s), shape (8,)."""
    return jax.grad(kinetic_energy, argnums=1)(e, e_dot, c, rhoA, L)


def inertial_forces(e, e_dot, c, c_dot, rhoA, L):
    """Velocity- and transport-dependent inertial forces (N), shape (8,).

    Lagrange's equations of the moving element read
    ``M e_ddot = dT/de - (d/dt)(dT/de_dot)|_{e_ddot=0} - dU/de + Q``; this returns
    ``dT/de - d(dT/de_dot)/de . e_dot - d(dT/de_dot)/dc . c_dot``: the gyroscopic
    (3.39), centrifugal (3.40) and transport-acceleration (rhoA dc/dt) terms.
    """
    dT_de = jax.grad(kinetic_energy, argnums=0)(e, e_dot, c, rhoA, L)
    _, dp = jax.jvp(
        lambda ee, cc: momentum(ee, e_dot, cc, rhoA, L), (e, c), (e_dot, jnp.asarray(c_dot, dtype=e.dtype))
    )
    return dT_de - dp


def elastic_forces(e, section: Section, L, bending="linear"):
    """Elastic forces -dU/de (N), shape (8,) (the negative of Q_k, eq. 3.14)."""
    return -jax.grad(strain_energy)(e, section, L, bending)


# --------------------------------------------------------------------------- matrices


def mass_matrix(rhoA, L):
    """Constant mass matrix d^2T/de_dot^2 (kg), shape (8, 8) (eq. 3.9)."""
    z = jnp.zeros(8)
    return jax.hessian(kinetic_energy, argnums=1)(z, z, 0.0, rhoA, L)


@jax.jit
def component_mass_matrix(rhoA, L):
    """Mass matrix (kg) of one displacement component (x or y) of the element, shape (4, 4),
    over that component of (r1, r1', r2, r2'): the (x, x) block of :func:`mass_matrix`, which
    does not couple the components (the cubic Hermite element's consistent mass, eq. 3.9)."""
    return mass_matrix(rhoA, L)[0::2, 0::2]


def gyroscopic_matrix(c, rhoA, L):
    """Skew gyroscopic matrix G (kg/s) of the linearised moving element (eq. 3.39).

    G = d(dT/de_dot)/de - (d(dT/de)/de_dot); independent of e because T is quadratic.
    """
    z = jnp.zeros(8)
    A = jax.jacfwd(momentum, argnums=0)(z, z, c, rhoA, L)
    return A - A.T


def centrifugal_matrix(c, rhoA, L):
    """Centrifugal stiffness K_c = -d^2T/de^2 (N/m) of the moving element (eq. 3.40)."""
    z = jnp.zeros(8)
    return -jax.hessian(kinetic_energy, argnums=0)(z, z, c, rhoA, L)


def tangent_stiffness(e, section: Section, L, bending="linear"):
    """Tangent elastic stiffness d^2U/de^2 (N/m) at coordinates e, shape (8, 8)."""
    return jax.hessian(strain_energy)(e, section, L, bending)


def axial_secant_matrix(e, EA, L):
    """Secant axial matrix K_l(e) = int EA eps S'^T S' dx with Q_l = K_l e (eq. 3.20-3.23).

    Built by autodiff: the Hessian in e2 of int EA eps(e) |r'(e2)|^2 / 2 dx with the
    strain frozen at e.
    """

    def frozen(e2):
        return _integrate(lambda xi: EA * axial_strain(e, xi, L) * 0.5 * (slope(e2, xi, L) @ slope(e2, xi, L)), L)

    return jax.hessian(frozen)(e)


def gravity_forces(rhoA, L, g=(0.0, -9.81)):
    """Generalised gravity forces -dV/de (N), shape (8,) (eq. 3.13)."""
    return -jax.grad(gravity_energy)(jnp.zeros(8), rhoA, L, g)
