"""Span components: how the belt between two pulleys is modelled.  The fidelity of a drive is
its choice of span component, made once by :func:`spans_of`:

- :class:`AncfSpans` (``fidelity = "ancf"``, the hybrid model): each span a chain of N
  nonlinear ANCF elements with the moving belt's inertia (thesis ch. 4);
- :class:`BarSpans` (``fidelity = "rotational"``, the Newton-Euler model): each span a
  massless axial bar between its end nodes (thesis eq. 4.15).

Both give the same interface: their independent coordinates, the nodes of the full vector,
the installed state, the mass, the potential and forces (elastic plus the listed effects, from
the energies by autodiff), the span tensions, and the reduced accelerations of the drive
(the ANCF spans' Schur-complement solve, the bars' span-length path).  Units: SI.
"""

from __future__ import annotations

import functools
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from beltjax import ancf, span
from beltjax.ancf import Section


class SpanModel(eqx.Module):
    """The interface of a span component (see the module docstring)."""

    #: the scene's ``model.fidelity`` that selects it
    fidelity: ClassVar[str] = ""
    #: whether the span nodes carry inertia (the belt's mass moves with them)
    massive: ClassVar[bool] = False
    #: default transient integrator and output interval (s)
    default_solver: ClassVar[str] = ""
    default_output_dt: ClassVar[float] = 1e-3

    @property
    def elements(self) -> int:
        """Elements per span in the full coordinates."""
        raise NotImplementedError

    @property
    def independent(self) -> int:
        """Independent coordinates per span (after the rigid ones)."""
        raise NotImplementedError

    def nodes(self, start, end, t_hat, body, stretch):
        """Full coordinates of one span (4 (N+1),): end nodes at ``start``, ``end`` (m) along
        ``t_hat``, the span's independent coordinates ``body`` (None for bars), stretch (-)."""
        raise NotImplementedError

    def installed(self, inst):
        """Independent span coordinates of the installed (straight) spans, flattened."""
        raise NotImplementedError

    def coordinate_index(self, n: int) -> np.ndarray:
        """Position in the full vector of each independent span coordinate (n spans)."""
        return np.zeros(0, dtype=int)

    def rigid_slide(self, t_hat):
        """The independent span coordinates of a 1 m rigid slide of the belt along its spans
        (t_hat (n, 2) the span directions), flattened."""
        return jnp.zeros(0, dtype=t_hat.dtype)

    def straight_shift(self, d0, d1, length):
        """The change of the independent span coordinates (flattened) that keeps every span
        straight when its end nodes move by d0, d1 ((n, 2) m); length (n,) m unstretched."""
        return jnp.zeros(0, dtype=d0.dtype)

    def mass_block(self, rhoA, Le):
        """Mass matrix of one span's full coordinates (kg), (4 (N+1), 4 (N+1))."""
        raise NotImplementedError

    def mass_per_length(self, rhoA):
        """The belt mass per length that the span's coordinates carry (kg/m)."""
        return rhoA if self.massive else 0.0 * rhoA

    def potential(self, e, belt, Le, c, effects):
        """Potential energy of one span (J) at coordinates e, transport speed c (m/s)."""
        raise NotImplementedError

    def forces(self, e, e_dot, belt, Le, c, c_dot, effects, dissipative=False):
        """Forces on one span's full coordinates (N): elastic plus the listed effects; belt
        damping only when ``dissipative`` (transients)."""
        raise NotImplementedError

    def tensions(self, E, EA, Le):
        """Mean axial force of each span (N), E (n, 4 (N+1)) span coordinates, Le (n,) m."""
        raise NotImplementedError

    def accelerations(self, qi, qi_dot, scene, inst, rm, t=None, speed=0.0, slip=None, Q=None):
        """The drive's reduced accelerations q_i'' (rad/s^2, m/s^2) with these spans; with the
        belt's slip states ``slip`` (m, :mod:`beltjax.drive.belt_slip`), (q_i'', their rates m/s).
        Q (n_i,): generalised forces (N, N m) added to the drive's own, or None."""
        raise NotImplementedError


class AncfSpans(SpanModel):
    """Spans as chains of ``n_elements`` ANCF beam elements (``bending``: "linear" or "exact")."""

    n_elements: int = eqx.field(static=True)
    bending: str = eqx.field(static=True, default="linear")
    fidelity: ClassVar[str] = "ancf"
    massive: ClassVar[bool] = True
    default_solver: ClassVar[str] = "generalized_alpha"
    default_output_dt: ClassVar[float] = 5e-4

    @property
    def elements(self) -> int:
        return self.n_elements

    @property
    def independent(self) -> int:
        return 4 * self.n_elements

    def nodes(self, start, end, t_hat, body, stretch):
        return jnp.concatenate([start, body[:2], body[2:-2], end, body[-2:]])

    def installed(self, inst):
        n, N = inst.span_start.shape[0], self.n_elements
        x = jnp.linspace(0.0, 1.0, N + 1)
        pos = inst.span_start[:, None, :] + x[None, :, None] * (inst.span_end - inst.span_start)[:, None, :]
        slope = jnp.broadcast_to((inst.stretch * inst.span_tangent)[:, None, :], (n, N + 1, 2))
        nodes = jnp.concatenate([pos, slope], axis=-1).reshape(n, 4 * (N + 1))
        return jnp.concatenate([nodes[:, 2 : 4 * N], nodes[:, 4 * N + 2 :]], axis=1).reshape(-1)  # drop end positions

    def coordinate_index(self, n: int) -> np.ndarray:
        N = self.n_elements
        local = np.r_[2 : 4 * N, 4 * N + 2 : 4 * N + 4]  # slopes of node 0, nodes 1..N-1, slopes of node N
        return (np.arange(n)[:, None] * 4 * (N + 1) + local[None, :]).reshape(-1)

    def rigid_slide(self, t_hat):
        n, N = t_hat.shape[0], self.n_elements
        node = jnp.concatenate([t_hat, jnp.zeros((n, 2))], axis=1)  # (n, 4): position, slope
        return jnp.concatenate([jnp.zeros((n, 2)), jnp.tile(node, (1, N - 1)), jnp.zeros((n, 2))], axis=1).reshape(-1)

    def straight_shift(self, d0, d1, length):
        n, N = d0.shape[0], self.n_elements
        x = jnp.linspace(0.0, 1.0, N + 1)
        dpos = (1 - x)[None, :, None] * d0[:, None, :] + x[None, :, None] * d1[:, None, :]
        dslope = jnp.broadcast_to(((d1 - d0) / length[:, None])[:, None, :], (n, N + 1, 2))
        dnodes = jnp.concatenate([dpos, dslope], axis=-1).reshape(n, 4 * (N + 1))
        return jnp.concatenate([dnodes[:, 2 : 4 * N], dnodes[:, 4 * N + 2 :]], axis=1).reshape(-1)

    def mass_block(self, rhoA, Le):
        return span.span_mass_matrix(rhoA, Le, span.element_index(self.n_elements))

    def potential(self, e, belt, Le, c, effects):
        idx = span.element_index(self.n_elements)
        U = span.span_strain_energy(e, Section(belt.EA, belt.EI, belt.rhoA), Le, idx, self.bending)
        extra = effects.span_potential(e, belt.rhoA, Le, idx)
        return U if extra is None else U + extra

    def forces(self, e, e_dot, belt, Le, c, c_dot, effects, dissipative=False):
        idx = span.element_index(self.n_elements)
        f = -jax.grad(self.potential)(e, belt, Le, c, effects)
        extra = effects.span_forces(e, e_dot, c, c_dot, belt, Le, idx, dissipative)
        return f if extra is None else f + extra

    def tensions(self, E, EA, Le):
        return jax.vmap(lambda e, le: jnp.mean(tension_profile(e, EA, le, self.n_elements)))(E, Le)

    def accelerations(self, qi, qi_dot, scene, inst, rm, t=None, speed=0.0, slip=None, Q=None):
        from beltjax.drive.equations import schur_accelerations

        if slip is not None:  # (belt_slip.transient_check refuses a hybrid transient with the effect)
            raise NotImplementedError("belt slip states are built for the rotational model's bars")
        return schur_accelerations(qi, qi_dot, scene, inst, rm, t, speed, Q)


class BarSpans(SpanModel):
    """Spans as massless axial bars between their end nodes (the rotational model)."""

    fidelity: ClassVar[str] = "rotational"
    default_solver: ClassVar[str] = "dopri8"
    default_output_dt: ClassVar[float] = 1e-3

    @property
    def elements(self) -> int:
        return 1

    @property
    def independent(self) -> int:
        return 0

    def nodes(self, start, end, t_hat, body, stretch):
        slope = stretch * t_hat  # slopes are not used by a bar
        return jnp.concatenate([start, slope, end, slope])

    def installed(self, inst):
        return jnp.zeros(0, dtype=inst.span_start.dtype)

    def mass_block(self, rhoA, Le):
        return jnp.zeros((8, 8))

    def potential(self, e, belt, Le, c, effects):
        d = e[4:6] - e[0:2]
        return bar_energy(d @ d, Le, belt.EA, belt.rhoA, effects.transport_speed(c))

    def forces(self, e, e_dot, belt, Le, c, c_dot, effects, dissipative=False):
        d = e[4:6] - e[0:2]
        length = jnp.linalg.norm(d)
        u = d / length
        damped = dissipative and "belt_damping" in effects
        rate = u @ (e_dot[4:6] - e_dot[0:2]) if damped else None
        N = bar_axial_force(length, rate, Le, belt, effects.transport_speed(c))
        return jnp.zeros(8, dtype=e.dtype).at[0:2].set(N * u).at[4:6].set(-N * u)

    def tensions(self, E, EA, Le):
        lam = jnp.linalg.norm(E[:, 4:6] - E[:, 0:2], axis=1) / Le
        return ancf.axial_force(lam, EA)

    def accelerations(self, qi, qi_dot, scene, inst, rm, t=None, speed=0.0, slip=None, Q=None):
        from beltjax.drive.rotational import bar_accelerations

        return bar_accelerations(qi, qi_dot, scene, inst, rm, t, speed, slip, Q)


def bar_energy(l2, L0, EA, rhoA, c):
    """Axial energy of a straight span as one bar of squared length l2 (m^2) and unstretched
    length L0 (m), minus its transport (centrifugal) term (J).

    Green-Lagrange, as the ANCF element: 1/2 EA L0 ((l/L0)^2 - 1)^2 / 4, so the axial force
    is EA (lam^2 - 1)/2 * lam with lam = l / L0; the moving belt's kinetic energy
    1/2 rhoA c^2 l^2 / L0 (c in m/s) acts as a negative potential (hub force reduced by rhoA v^2).
    """
    eps = 0.5 * (l2 / L0**2 - 1.0)
    return 0.5 * EA * L0 * eps**2 - 0.5 * rhoA * c**2 * l2 / L0


def bar_axial_force(length, rate, L0, belt, c=0.0):
    """Axial force (N) of a bar span of length ``length`` (m) and unstretched length ``L0`` (m):
    dV/dl of :func:`bar_energy` (less the centrifugal term of transport speed ``c`` m/s), plus
    the belt's viscous force CA / L0 dl/dt (thesis eq. 4.15) when ``rate`` (dl/dt, m/s) is
    given.  The one bar law of the rotational model."""
    N = jax.grad(bar_energy)(length * length, L0, belt.EA, belt.rhoA, c) * (2 * length)
    return N if rate is None else N + belt.CA / L0 * rate


def tension_profile(e, EA, Le, N):
    """Axial force EA eps |r'| (N) at each element's midpoint of an ANCF span, shape (N,)."""
    idx = span.element_index(N)

    def one(ee):
        rp = ancf.slope(ee, 0.5, Le)
        return ancf.axial_force(jnp.sqrt(rp @ rp), EA)

    return jax.vmap(one)(e[idx])


@functools.lru_cache(maxsize=None)
def _component(fidelity: str, n_elements: int, bending: str) -> SpanModel:
    if fidelity == AncfSpans.fidelity:
        return AncfSpans(n_elements, bending)
    if fidelity == BarSpans.fidelity:
        return BarSpans()
    raise ValueError(f"unknown fidelity {fidelity!r}; known: ancf, rotational")


def spans_of(scene) -> SpanModel:
    """The span component of ``scene`` (its ``model.fidelity``), built once per mesh."""
    m = scene.model
    return _component(m.fidelity, int(m.elements_per_span), str(m.bending))
