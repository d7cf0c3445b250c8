"""The effects a scene may list, each one module, and their assembly.

Each effect is an :class:`Effect` (an equinox module) that says which scene parameters it owns
and contributes through one small interface: a span's potential (J), a span's generalised
forces (N), the bodies' forces (N, N m), the drive pulley's angle (rad).  (Unbalance and the
bodies' weights are still applied where the kinematics and the body forces need the
installation; they ask the assembly whether the effect is listed.)  An effect that is not listed is not in the assembly and adds nothing (not even
a zero) to any traced program: :func:`effects_of` is the one place where the names in
``model.effects`` are switched, and the one place that maps a name to a module.

Effects (units of the parameters they own):

- ``transport``: the axially moving belt; its speed c (m/s) enters the spans' gyroscopic,
  centrifugal and rhoA dc/dt terms and the bars' centrifugal term;
- ``gravity``: the weight of belt, pulleys and tensioner (g = 9.81 m/s^2, -y);
- ``belt_damping``: viscous axial damping of the belt, belt.CA (N s);
- ``bearing_damping``: pulley.bearing_damping (N m s/rad) on each pulley's absolute speed;
- ``tensioner_damping``: tensioner.damping (N m s/rad) on the arm's speed;
- ``unbalance``: pulley.cm_offset (m), the centre of mass off the axis;
- ``speed_fluctuation``: pulley.fluctuation_amplitude_deg / _frequency_hz, a harmonic
  fluctuation of a driven pulley's angle.
"""

from __future__ import annotations

import functools
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from beltjax import ancf, span
from beltjax.scene.spec import EFFECTS, TENSIONER, Scene


class Effect(eqx.Module):
    """One effect: its name, the parameters it owns, and what it contributes (nothing by default)."""

    name: ClassVar[str] = ""
    #: whether its span forces dissipate (left out of the conservative statics and modal forces)
    dissipative: ClassVar[bool] = False

    def given(self, scene: Scene) -> list[str]:
        """Keys of this effect's parameters that ``scene`` gives a non-zero value."""
        return []

    def span_potential(self, e, rhoA, Le, idx):
        """Potential of one ANCF span (J), or None."""
        return None

    def span_forces(self, e, e_dot, c, c_dot, belt, Le, idx):
        """Generalised forces on one ANCF span (N) in a transient, or None (belt: the scene's belt)."""
        return None

    def body_forces(self, f, bodies, bodies_dot, scene: Scene, t):
        """``f`` (nb, 3; N, N m) plus this effect's forces on the bodies in a transient."""
        return f

    def drive_angle(self, angle, pulley, t):
        """The drive pulley's angle (rad) at time t (s) with this effect."""
        return angle


class Transport(Effect):
    """The axially moving belt (gyroscopic, centrifugal and rhoA dc/dt terms)."""

    name: ClassVar[str] = "transport"

    def span_forces(self, e, e_dot, c, c_dot, belt, Le, idx):
        return span.span_inertial_forces(e, e_dot, c, c_dot, belt.rhoA, Le, idx)


class Gravity(Effect):
    """The weight of belt, pulleys and tensioner (the bodies' weights are applied by the drive's
    body forces, which need the installation's wrapped-belt masses)."""

    name: ClassVar[str] = "gravity"

    def span_potential(self, e, rhoA, Le, idx):
        from beltjax.drive.topology import GRAVITY

        return jnp.sum(jax.vmap(ancf.gravity_energy, in_axes=(0, None, None, None))(e[idx], rhoA, Le, GRAVITY))


def _element_dissipation(e, e_dot, CA, L):
    """Rayleigh function of an element (W): 1/2 int CA (r'.r'_t)^2 dx (Green-Lagrange strain rate)."""

    def density(xi):
        return 0.5 * CA * (ancf.slope(e, xi, L) @ ancf.slope(e_dot, xi, L)) ** 2

    return L * jnp.sum(ancf.WEIGHTS * jax.vmap(density)(ancf.XI))


def span_dissipation(e, e_dot, CA, Le, idx):
    """Rayleigh function of an ANCF span (W) with belt damping CA (N s)."""
    return jnp.sum(jax.vmap(_element_dissipation, in_axes=(0, 0, None, None))(e[idx], e_dot[idx], CA, Le))


class BeltDamping(Effect):
    """Viscous axial damping of the belt, CA (N s): Rayleigh function 1/2 int CA (d eps/dt)^2 dx
    on ANCF spans, CA / L0 dl/dt on bars."""

    name: ClassVar[str] = "belt_damping"
    dissipative: ClassVar[bool] = True

    def given(self, scene):
        return ["belt.CA"] if float(scene.belt.CA) > 0 else []

    def span_forces(self, e, e_dot, c, c_dot, belt, Le, idx):
        return -jax.grad(span_dissipation, argnums=1)(e, e_dot, belt.CA, Le, idx)


class BearingDamping(Effect):
    """Viscous bearing damping: -c_b times each pulley's absolute speed (N m s/rad)."""

    name: ClassVar[str] = "bearing_damping"

    def given(self, scene):
        return [f"pulley[{i}].bearing_damping" for i, p in enumerate(scene.pulleys) if float(p.bearing_damping) > 0]

    def body_forces(self, f, bodies, bodies_dot, scene, t):
        for i, name in enumerate(scene.route.order):
            if name != TENSIONER:
                f = f.at[i, 2].add(-scene.pulley(name).bearing_damping * bodies_dot[i, 2])
        return f


class TensionerDamping(Effect):
    """Viscous damping at the tensioner pivot: -c times the arm's speed (N m s/rad)."""

    name: ClassVar[str] = "tensioner_damping"

    def given(self, scene):
        return ["tensioner.damping"] if scene.tensioner is not None and float(scene.tensioner.damping) > 0 else []

    def body_forces(self, f, bodies, bodies_dot, scene, t):
        if scene.tensioner is None:
            return f
        return f.at[-1, 2].add(-scene.tensioner.damping * bodies_dot[-1, 2])


class Unbalance(Effect):
    """Pulley centres of mass off the axis by cm_offset (m, in the pulley's frame)."""

    name: ClassVar[str] = "unbalance"

    def given(self, scene):
        return [f"pulley[{i}].cm_offset" for i, p in enumerate(scene.pulleys)
                if float(jnp.linalg.norm(p.cm_offset)) > 0]


class SpeedFluctuation(Effect):
    """A harmonic fluctuation A sin(2 pi f t) of a driven pulley's angle (deg, Hz)."""

    name: ClassVar[str] = "speed_fluctuation"

    def given(self, scene):
        return [f"pulley[{i}].fluctuation_amplitude_deg" for i, p in enumerate(scene.pulleys)
                if float(p.fluctuation_amplitude_deg) > 0]

    def drive_angle(self, angle, pulley, t):
        A = jnp.deg2rad(pulley.fluctuation_amplitude_deg)
        return angle + A * jnp.sin(2 * jnp.pi * pulley.fluctuation_frequency_hz * t)


#: every effect module, by the name a scene lists
MODULES: dict[str, type[Effect]] = {m.name: m for m in (Transport, Gravity, BeltDamping, BearingDamping,
                                                          TensionerDamping, Unbalance, SpeedFluctuation)}
assert tuple(MODULES) == EFFECTS


class Effects(eqx.Module):
    """The listed effects of a scene, assembled once (:func:`effects_of`)."""

    listed: tuple[Effect, ...]
    names: frozenset = eqx.field(static=True)

    def __contains__(self, name: str) -> bool:
        if name not in MODULES:
            raise ValueError(f"unknown effect {name!r}; known: {', '.join(MODULES)}")
        return name in self.names

    @property
    def moving_belt(self) -> bool:
        """Whether the belt's transport speed enters the equations (gyroscopic, centrifugal)."""
        return "transport" in self

    def transport_speed(self, c):
        """The transport speed the equations see (m/s): c with transport, else 0."""
        return c if self.moving_belt else 0.0

    def span_potential(self, e, rhoA, Le, idx):
        """Sum of the listed effects' span potentials (J), or None."""
        terms = [u for u in (x.span_potential(e, rhoA, Le, idx) for x in self.listed) if u is not None]
        return sum(terms[1:], terms[0]) if terms else None

    def span_forces(self, e, e_dot, c, c_dot, belt, Le, idx, dissipative: bool):
        """Sum of the listed effects' span forces (N), or None; damping only when ``dissipative``."""
        out = None
        for x in self.listed:
            if x.dissipative and not dissipative:
                continue
            f = x.span_forces(e, e_dot, c, c_dot, belt, Le, idx)
            if f is not None:
                out = f if out is None else out + f
        return out

    def body_forces(self, f, bodies, bodies_dot, scene, t):
        """``f`` plus the listed effects' forces on the bodies in a transient (N, N m)."""
        for x in self.listed:
            f = x.body_forces(f, bodies, bodies_dot, scene, t)
        return f

    def drive_angle(self, angle, pulley, t):
        """The drive pulley's angle (rad) at time t with the listed effects."""
        for x in self.listed:
            angle = x.drive_angle(angle, pulley, t)
        return angle

    def unlisted_parameters(self, scene: Scene) -> list[tuple[str, str]]:
        """(key, effect) of every parameter given while its effect is not listed."""
        return [(k, name) for name, m in MODULES.items() if name not in self.names for k in m().given(scene)]


@functools.lru_cache(maxsize=None)
def _assemble(names: tuple[str, ...]) -> Effects:
    for n in names:
        if n not in MODULES:
            raise ValueError(f"unknown effect {n!r}; known: {', '.join(MODULES)}")
    return Effects(tuple(MODULES[n]() for n in MODULES if n in names), frozenset(names))


def effects_of(scene: Scene) -> Effects:
    """The listed effects of ``scene`` as modules (assembled once per list of names)."""
    return _assemble(tuple(scene.model.effects))
