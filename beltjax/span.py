"""Span analysis: one belt span under tension, linearised about its static state.

A span of length ``length`` (m, between the pins / pulley tangent points) is
meshed with ``n_elements`` ANCF elements along +x.  Its pre-tensioned static
state is the straight span at the uniform stretch ``lam`` whose Green-Lagrange
axial force ``EA (lam^2 - 1)/2 * lam`` equals the tension T; element
reference lengths are unstretched (``length / (n_elements * lam)``).  It is an
exact equilibrium of the discrete model for any BC, as a uniform stretch is
represented exactly by the cubic element.

The mass, gyroscopic and stiffness matrices (elastic tangent plus centrifugal)
are second derivatives, by autodiff, of the span's total kinetic and
potential energies, the element energies being vmapped over the elements.
Boundary conditions per end:

* ``pinned``  position fixed, slope free (the thesis' condition at pulleys);
* ``clamped`` position and slope fixed;
* ``free``    nothing fixed (the cantilever's tip).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from beltjax import ancf, modal, schema
from beltjax.ancf import BENDING_MODELS, Section
from beltjax.errors import BeltjaxError

BOUNDARY_CONDITIONS = ("pinned", "clamped", "free")
#: most elements of a span (as a scene's model.elements_per_span)
MAX_ELEMENTS = 400


# --------------------------------------------------------------------------- assembly


def element_index(n_elements: int) -> np.ndarray:
    """Global coordinate indices of each element, shape (n_elements, 8).

    A span of N elements has N + 1 nodes of 4 coordinates (x, y, x', y').
    """
    return 4 * np.arange(n_elements)[:, None] + np.arange(8)[None, :]


def span_kinetic_energy(q, q_dot, c, rhoA, L0, idx):
    """Kinetic energy of a span (J): element energies vmapped and summed."""
    T = jax.vmap(ancf.kinetic_energy, in_axes=(0, 0, None, None, None))(q[idx], q_dot[idx], c, rhoA, L0)
    return jnp.sum(T)


def span_strain_energy(q, section: Section, L0, idx, bending="linear"):
    """Elastic energy of a span (J): element energies vmapped and summed."""
    U = jax.vmap(ancf.strain_energy, in_axes=(0, None, None, None))(q[idx], section, L0, bending)
    return jnp.sum(U)


def span_mass_matrix(rhoA, L0, idx):
    """Constant mass matrix d^2T/dq_dot^2 of a span (kg), all coordinates."""
    z = jnp.zeros(int(np.max(idx)) + 1)
    return jax.hessian(span_kinetic_energy, argnums=1)(z, z, 0.0, rhoA, L0, idx)


def span_component_mass(rhoA, Le, n_elements: int):
    """Assembled mass (kg) of one displacement component of a span of ``n_elements`` equal
    elements of length Le (m), shape (2 (N+1), 2 (N+1)), over (r_k, r_k') of node k of that
    component (from :func:`beltjax.ancf.component_mass_matrix`, so from the kinetic energy)."""
    m = ancf.component_mass_matrix(rhoA, Le)
    idx = 2 * np.arange(n_elements)[:, None] + np.arange(4)[None, :]
    size = 2 * (n_elements + 1)
    blocks = jnp.broadcast_to(m, (n_elements, 4, 4))
    return jnp.zeros((size, size), dtype=m.dtype).at[idx[:, :, None], idx[:, None, :]].add(blocks)


def span_inertial_forces(q, q_dot, c, c_dot, rhoA, L0, idx):
    """Assembled velocity and transport inertial forces of a span (N): ``ancf.inertial_forces`` summed."""
    f = jax.vmap(ancf.inertial_forces, in_axes=(0, 0, None, None, None, None))(q[idx], q_dot[idx], c, c_dot, rhoA, L0)
    return jnp.zeros_like(q).at[idx].add(f)


def span_elastic_forces(q, section: Section, L0, idx, bending="linear"):
    """Assembled elastic forces -dU/dq of a span (N), shape (4 (N+1),)."""
    return -jax.grad(span_strain_energy)(q, section, L0, idx, bending)


def stretch_for_tension(T, EA):
    """Uniform stretch lam with EA (lam^2 - 1)/2 * lam = T (Green-Lagrange axial force), by Newton."""
    lam = 1.0 + T / EA
    for _ in range(8):
        lam = lam - (ancf.axial_force(lam, EA) - T) / ancf.axial_force_slope(lam, EA)
    return lam


def straight_state(n_elements: int, length, lam):
    """Coordinates of a straight span along +x from the origin, at stretch lam."""
    x = jnp.linspace(0.0, 1.0, n_elements + 1) * length
    z = jnp.zeros_like(x)
    return jnp.stack([x, z, jnp.full_like(x, lam), z], axis=1).reshape(-1)


def free_dofs(n_elements: int, bc: tuple[str, str]) -> np.ndarray:
    """Indices of the unconstrained coordinates for the end conditions bc = (left, right)."""
    n = 4 * (n_elements + 1)
    fixed = []
    for end, base in ((bc[0], 0), (bc[1], n - 4)):
        if end == "pinned":
            fixed += [base, base + 1]
        elif end == "clamped":
            fixed += [base, base + 1, base + 2, base + 3]
        elif end != "free":
            raise ValueError(f"boundary condition must be one of {BOUNDARY_CONDITIONS}, got {end!r}")
    return np.setdiff1d(np.arange(n), fixed)


@partial(jax.jit, static_argnames=("n_elements", "bc", "bending"))
def span_matrices(section: Section, length, tension, speed, *, n_elements: int, bc=("pinned", "pinned"), bending="linear"):
    """Reduced M, G, K (free coordinates) of a span linearised about its static state.

    section: Section (N, N m^2, kg/m); length (m); tension (N); speed: spatial belt
    speed (m/s).  Returns a dict with M, G, K, the static coordinates q0, the
    stretch lam and the element reference length L0.
    """
    idx = element_index(n_elements)
    free = free_dofs(n_elements, bc)
    lam = stretch_for_tension(tension, section.EA)
    L0 = length / (n_elements * lam)
    c = speed / lam  # unstretched length per second
    q0 = straight_state(n_elements, length, lam)
    z = jnp.zeros_like(q0)

    def kin(q, qd):
        return span_kinetic_energy(q, qd, c, section.rhoA, L0, idx)

    def pot(q):
        return span_strain_energy(q, section, L0, idx, bending)

    M = span_mass_matrix(section.rhoA, L0, idx)
    dp_dq = jax.jacfwd(jax.grad(kin, argnums=1), argnums=0)(q0, z)
    G = dp_dq - dp_dq.T
    K = jax.hessian(pot)(q0) - jax.hessian(kin, argnums=0)(q0, z)
    sel = jnp.ix_(free, free)
    return dict(M=M[sel], G=G[sel], K=K[sel], q0=q0, lam=lam, L0=L0)


# --------------------------------------------------------------------------- results


@dataclass
class SpanResult:
    """Natural frequencies and modes of a span; see ``analyse_span``.

    frequencies_hz: ascending natural frequencies (Hz), empty when unstable;
    labels: e.g. "2nd transverse"; stable: False past the critical speed;
    unstable_eigenvalues: eigenvalues (1/s) with positive real part, or, for a span that
    only gyroscopic coupling holds past a critical speed (stiffness indefinite, every
    eigenvalue imaginary), those of its negative-energy modes, which any damping makes grow
    (see :mod:`beltjax.modal`);
    critical_speed_m_s: speed at which the transverse stiffness vanishes;
    mode_shapes: (n_coordinates, n_modes) displacement shapes on all coordinates
    (zeros at fixed ones), real parts of complex gyroscopic modes.
    """

    length: float
    tension: float
    speed: float
    section: Section
    n_elements: int
    bc: tuple[str, str]
    bending: str
    stretch: float
    critical_speed_m_s: float
    stable: bool
    frequencies_hz: np.ndarray
    labels: list[str]
    transverse_share: np.ndarray
    unstable_eigenvalues: np.ndarray
    mode_shapes: np.ndarray = field(repr=False)
    static_state: np.ndarray = field(repr=False)
    element_length: float = 0.0

    def to_json(self, n_modes: int | None = None) -> dict:
        """The result as a JSON-serialisable dict (the contents of span.json)."""
        k = len(self.frequencies_hz) if n_modes is None else min(n_modes, len(self.frequencies_hz))
        return {
            "length_m": self.length,
            "tension_N": self.tension,
            "speed_m_s": self.speed,
            "EA_N": float(self.section.EA),
            "EI_Nm2": float(self.section.EI),
            "rhoA_kg_m": float(self.section.rhoA),
            "elements": self.n_elements,
            "bc": list(self.bc),
            "bending": self.bending,
            "stretch": self.stretch,
            "critical_speed_m_s": self.critical_speed_m_s,
            "stable": self.stable,
            "frequencies_hz": [float(f) for f in self.frequencies_hz[:k]],
            "labels": self.labels[:k],
            "transverse_share": [float(s) for s in self.transverse_share[:k]],
            "unstable_eigenvalues": [[float(l.real), float(l.imag)] for l in self.unstable_eigenvalues],
        }


def _label_modes(shapes, M_free, free):
    """Transverse share (mass-weighted, y coordinates) and labels of each mode."""
    is_y = (free % 2 == 1)[:, None]
    M = np.asarray(M_free)
    py, px = np.where(is_y, shapes, 0), np.where(is_y, 0, shapes)
    ey = np.real(np.sum(np.conj(py) * (M @ py), axis=0))
    ex = np.real(np.sum(np.conj(px) * (M @ px), axis=0))
    shares = np.where(ey + ex > 0, ey / np.where(ey + ex > 0, ey + ex, 1.0), 0.0)
    labels, counts = [], {"transverse": 0, "longitudinal": 0}
    for share in shares:
        kind = "transverse" if share >= 0.5 else "longitudinal"
        counts[kind] += 1
        labels.append(f"{modal.ordinal(counts[kind])} {kind}")
    return shares, labels


def check_arguments(length, tension, EA, EI, rhoA, speed=0.0, n_elements=20, bc="pinned", bending="linear", *,
                    keys=None):
    """The arguments of :func:`analyse_span` as floats, an int and a (left, right) pair, or a
    :class:`BeltjaxError` naming the argument: numbers in their :mod:`beltjax.schema` ranges
    (length as ``span.length``, tension ``span.tension``, speed ``span.speed``, EA, EI and rhoA
    as the belt's), and a span that float64 can carry (:func:`beltjax.schema.string_spread`).
    keys: {argument: name in messages} (the command line's ``--length``, ...)."""
    key = {k: k for k in ("length", "tension", "EA", "EI", "rhoA", "speed")} | dict(keys or {})
    length = schema.number(length, key["length"], "span.length")
    tension = schema.number(tension, key["tension"], "span.tension")
    EA, EI, rhoA = (schema.number(x, key[k], f"belt.{k}") for k, x in (("EA", EA), ("EI", EI), ("rhoA", rhoA)))
    speed = schema.number(speed, key["speed"], "span.speed")
    if (isinstance(n_elements, bool) or not isinstance(n_elements, (int, np.integer))
            or not 1 <= n_elements <= MAX_ELEMENTS):
        raise BeltjaxError(f"must be an integer from 1 to {MAX_ELEMENTS}, got {n_elements!r}", "n_elements")
    pair = (bc, bc) if isinstance(bc, str) else tuple(bc) if isinstance(bc, (tuple, list)) else None
    if pair is None or len(pair) != 2 or any(b not in BOUNDARY_CONDITIONS for b in pair):
        raise BeltjaxError(f"expected one of {', '.join(BOUNDARY_CONDITIONS)} or a (left, right) pair of them, "
                           f"got {bc!r}", "bc")
    if pair == ("free", "free"):
        raise BeltjaxError("a span free at both ends is not held: pin or clamp one end", "bc")
    if bending not in BENDING_MODELS:
        raise BeltjaxError(f"expected one of {', '.join(BENDING_MODELS)}, got {bending!r}", "bending")
    if EI == 0.0 and tension == 0.0:
        raise BeltjaxError("a string (EI = 0) without tension has no transverse stiffness: give tension > 0",
                           key["tension"])
    spread = float(schema.string_spread(EA, EI, tension, length, n_elements))
    if not spread <= schema.MAX_STRING_SPREAD:
        raise BeltjaxError(
            f"the axial stiffness ({EA:g} N over {n_elements} elements) is {spread:.3g} times the string stiffness "
            f"(tension {tension:g} N, EI {EI:g} N m^2; at most {schema.MAX_STRING_SPREAD:g}), beyond what float64 "
            "eigen-solves resolve (check EA's unit, or use fewer elements)", key["EA"])
    return length, tension, EA, EI, rhoA, speed, int(n_elements), pair


def analyse_span(
    length: float,
    tension: float,
    EA: float,
    EI: float,
    rhoA: float,
    *,
    speed: float = 0.0,
    n_elements: int = 20,
    bc: str | tuple[str, str] = "pinned",
    bending: str = "linear",
) -> SpanResult:
    """Natural frequencies and mode shapes of a tensioned, possibly moving, span.

    length: span length between the supports (m); tension: static tension (N);
    EA (N), EI (N m^2), rhoA (kg per m of unstretched belt); speed: belt speed
    through the span (m/s); n_elements: ANCF elements; bc: "pinned", "clamped"
    or a (left, right) pair including "free"; bending: "linear" or "exact".
    With speed != 0 the gyroscopic eigenproblem is solved; past the critical
    speed the result has ``stable=False`` and the unstable eigenvalues.  Bad arguments (NaN,
    out of range, see :func:`check_arguments`) raise :class:`beltjax.errors.BeltjaxError`.
    """
    length, tension, EA, EI, rhoA, speed, n_elements, bc = check_arguments(
        length, tension, EA, EI, rhoA, speed, n_elements, bc, bending)
    section = Section(EA, EI, rhoA)
    mats = span_matrices(section, float(length), float(tension), float(speed), n_elements=n_elements, bc=bc, bending=bending)
    free = free_dofs(n_elements, bc)
    n_coords = 4 * (n_elements + 1)
    lam = float(mats["lam"])
    if speed == 0.0:
        omega2, V = modal.symmetric_modes(mats["M"], mats["K"])
        omega2, V = np.asarray(omega2), np.asarray(V)
        stable = bool(modal.is_stable_omega2(omega2))
        if stable:
            freqs = np.sqrt(np.clip(omega2, 0.0, None)) / (2 * np.pi)
            unstable = np.zeros(0, complex)
        else:
            freqs, V = np.zeros(0), np.zeros((len(free), 0))
            unstable = np.sqrt(-omega2[omega2 < 0].astype(complex)).real.astype(complex)
    else:
        stable, freqs, V, unstable = modal.gyroscopic_modes(mats["M"], mats["G"], mats["K"])
    shares, labels = _label_modes(V, mats["M"], free)
    shapes = np.zeros((n_coords, V.shape[1]))
    if V.shape[1]:
        Vr = V
        if np.iscomplexobj(V):  # rotate each complex mode so its real part carries most of it
            Vr = np.real(V * np.exp(-1j * np.angle(np.sum(V**2, axis=0)) / 2))
        shapes[free, :] = Vr / np.max(np.abs(Vr), axis=0, keepdims=True)
    # transverse stiffness T_elastic - rhoA_spatial v^2 vanishes at v = sqrt(T lam / rhoA)
    v_crit = float(np.sqrt(tension * lam / rhoA)) if tension > 0 else 0.0
    return SpanResult(
        length=float(length), tension=float(tension), speed=float(speed), section=section,
        n_elements=n_elements, bc=bc, bending=bending, stretch=lam, critical_speed_m_s=v_crit,
        stable=stable, frequencies_hz=np.asarray(freqs), labels=labels, transverse_share=shares,
        unstable_eigenvalues=np.asarray(unstable), mode_shapes=shapes,
        static_state=np.asarray(mats["q0"]), element_length=float(mats["L0"]),
    )
