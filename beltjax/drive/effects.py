"""The effects a scene may list, each one module, and their assembly.

Each effect is an :class:`Effect` (an equinox module).  The parameters it owns are the schema's
fields that name it (:data:`beltjax.schema.FIELDS`, a field's ``effect``: the one list that also
serves scene parsing, parameter paths and sweep and optimisation bounds).  It contributes through
one small interface: a span's potential (J), a span's generalised forces (N), the bodies' forces
(N, N m) in transients and in steady states, the bodies' positions (m), the drive pulley's
angle (rad), and a force that depends on the accelerations themselves (N m: the transient's
accelerations as a function of added generalised forces).  An effect that is not listed is not
in the assembly and adds nothing (not even a zero) to any traced program: :func:`effects_of` is
the one place where the names in ``model.effects`` are switched, and the one place that maps a
name to a module.

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
- ``tensioner_friction``: tensioner.friction_moment (N m), friction_asymmetry (-),
  friction_speed (rad/s), friction_stick_time (s): dry friction at the tensioner pivot
  (:mod:`beltjax.drive.pivot`), a moment that depends on the accelerations.
- ``belt_slip``: belt.slip_speed (m/s): creep and gross slip of the belt on every wrapped arc,
  three states per arc in the transient (:mod:`beltjax.drive.belt_slip`; rotational model), and
  the running belt's compatibility in the operating point (:func:`beltjax.statics.equilibrium`).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from beltjax import ancf, schema, span
from beltjax.drive import pivot
from beltjax.scene.spec import EFFECTS, TENSIONER, Scene


class Effect(eqx.Module):
    """One effect: its name, the parameters it owns, and what it contributes (nothing by default)."""

    name: ClassVar[str] = ""
    #: whether its span forces dissipate (left out of the conservative statics and modal forces)
    dissipative: ClassVar[bool] = False

    def parameters(self) -> list[str]:
        """The schema keys this effect owns (``beltjax.schema.FIELDS``: a field's ``effect``)."""
        return [k for k, f in schema.FIELDS.items() if f.effect == self.name]

    def given(self, scene: Scene) -> list[str]:
        """Scene keys of this effect's parameters that ``scene`` gives a value other than its
        default (the field's default in :mod:`beltjax.scene.spec`, else 0): ``belt.CA``,
        ``pulley[1].cm_offset``, ``tensioner.damping``."""
        out = []
        for key in self.parameters():
            group, attr = key.split(".")
            field = attr  # the scene dataclass's field that holds the key's value
            if group == "belt":
                owners = [("belt", scene.belt)]
            elif group == "pulley":
                owners = [(f"pulley[{i}]", p) for i, p in enumerate(scene.pulleys)]
            elif group == "fluctuation":  # order or frequency_hz, whichever the table gives, is the field rate
                field = "rate" if attr in ("order", "frequency_hz") else attr
                owners = [(x.key or f"fluctuation[{i}]", x) for i, x in enumerate(scene.fluctuations)
                          if field != "rate" or (attr == "order") == (x.per == "rev")]
            else:
                owners = [(group, getattr(scene, group))] if getattr(scene, group) is not None else []
            for prefix, obj in owners:
                v = getattr(obj, field)
                default = _defaults(type(obj)).get(field, 0.0)
                if v is not None and float(np.max(np.abs(np.asarray(v) - default))) > 0:
                    out.append(f"{prefix}.{attr}")
        return out

    def span_potential(self, e, rhoA, Le, idx):
        """Potential of one ANCF span (J), or None."""
        return None

    def span_forces(self, e, e_dot, c, c_dot, belt, Le, idx):
        """Generalised forces on one ANCF span (N) in a transient, or None (belt: the scene's belt)."""
        return None

    def body_forces(self, f, bodies, bodies_dot, scene: Scene, t):
        """``f`` (nb, 3; N, N m) plus this effect's forces on the bodies in a transient."""
        return f

    def steady_body_forces(self, f, masses, scene: Scene, inst, transient: bool):
        """``f`` (nb, 3; N, N m) plus this effect's conservative forces on the bodies (statics,
        modes and transients); masses (nb, 3): the bodies' (m, m, J) (kg, kg m^2); inst: the
        installation or None."""
        return f

    def body_positions(self, pos, angle, scene: Scene, inst):
        """The route entries' body positions (n, 2) m given their centres ``pos`` and angles
        ``angle`` (n,) rad."""
        return pos

    def drive_angle(self, angle, pulley, t, scene: Scene, speed_rpm):
        """What this effect adds to the drive pulley's angle (rad) at time t (s), ``angle`` its
        mean rotation (rad), ``speed_rpm`` its nominal speed then (rpm); None for nothing."""
        return None

    def accelerations(self, acc, qi, qi_dot, scene: Scene, inst, t):
        """The transient's accelerations as a function of added generalised forces Q (n_i,; N,
        N m; or None), given ``acc``, the drive's own such function: this effect's force where it
        depends on the accelerations themselves (a constraint-like force); ``acc`` for nothing."""
        return acc


@functools.lru_cache(maxsize=None)
def _defaults(cls) -> dict:
    """{field: default} of a scene dataclass's fields that have one."""
    return {f.name: f.default for f in dataclasses.fields(cls) if f.default is not dataclasses.MISSING}


class Transport(Effect):
    """The axially moving belt (gyroscopic, centrifugal and rhoA dc/dt terms)."""

    name: ClassVar[str] = "transport"

    def span_forces(self, e, e_dot, c, c_dot, belt, Le, idx):
        return span.span_inertial_forces(e, e_dot, c, c_dot, belt.rhoA, Le, idx)


GRAVITY = (0.0, -9.81)  # m/s^2


class Gravity(Effect):
    """The weight of belt, pulleys (with their wrapped belt) and tensioner, g = 9.81 m/s^2 along -y."""

    name: ClassVar[str] = "gravity"

    def span_potential(self, e, rhoA, Le, idx):
        return jnp.sum(jax.vmap(ancf.gravity_energy, in_axes=(0, None, None, None))(e[idx], rhoA, Le, GRAVITY))

    def steady_body_forces(self, f, masses, scene, inst, transient):
        from beltjax.drive.assembly import drive_of

        f = f.at[:, 1].add(GRAVITY[1] * masses[:, 0])
        if inst is not None and drive_of(scene).spans.massive:  # the belt's weight on its spans
            f = f.at[: len(scene.route.order), 2].add(belt_weight_slide_moments(scene, inst, transient))
        return f


def belt_weight_slide_moments(scene: Scene, inst, transient: bool = False):
    """Moments (N m) on the pulleys that make a rigid turn of the belt loop cost no weight.

    A pulley's rotation perturbation slides the span end nodes along their spans (s R phi);
    the belt itself flows through the spans, so sliding a span along its own line must not
    move its weight.  The span's weight is counted with its nodes shifted back by the
    interpolated end slides, (1 - x) s0 + x s1 along the span: that adds the potential
    rhoA (g . t) L0 (s0 + s1) / 2 per span, i.e. these constant moments (a pure moment: the
    bearing forces are unchanged).  In a transient whose belt travels with a free drive
    pulley (``travel_follows_drive``) the slides are taken relative to that travel,
    s R phi - s_d R_d phi_d, which adds to the drive pulley's moment minus s_d R_d times the
    others' sum of m_i / (s_i R_i): a rigid turn of the loop, which then moves no node, does no
    work either.
    """
    from beltjax.drive.assembly import drive_of

    n = len(scene.route.order)
    g = jnp.asarray(GRAVITY)
    L0 = inst.span_length / inst.stretch  # unstretched span lengths (m)
    senses = jnp.asarray(scene.route.senses, dtype=L0.dtype)
    w = scene.belt.rhoA * (inst.span_tangent @ g) * L0 / 2  # per span, N
    prev = (np.arange(n) - 1) % n
    m = -(w + w[prev]) * senses * inst.radii
    d = drive_of(scene)
    if transient and d.travel_follows_drive:
        k = d.drive_pulley
        m = m.at[k].add(-senses[k] * inst.radii[k] * jnp.sum(m / (senses * inst.radii)))
    return m


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


    def span_forces(self, e, e_dot, c, c_dot, belt, Le, idx):
        return -jax.grad(span_dissipation, argnums=1)(e, e_dot, belt.CA, Le, idx)


class BearingDamping(Effect):
    """Viscous bearing damping: -c_b times each pulley's absolute speed (N m s/rad)."""

    name: ClassVar[str] = "bearing_damping"


    def body_forces(self, f, bodies, bodies_dot, scene, t):
        for i, name in enumerate(scene.route.order):
            if name != TENSIONER:
                f = f.at[i, 2].add(-scene.pulley(name).bearing_damping * bodies_dot[i, 2])
        return f


class TensionerDamping(Effect):
    """Viscous damping at the tensioner pivot: -c times the arm's speed (N m s/rad)."""

    name: ClassVar[str] = "tensioner_damping"


    def body_forces(self, f, bodies, bodies_dot, scene, t):
        if scene.tensioner is None:
            return f
        return f.at[-1, 2].add(-scene.tensioner.damping * bodies_dot[-1, 2])


class TensionerFriction(Effect):
    """Dry friction at the tensioner pivot: optionally asymmetric Coulomb by a regularised switch
    model (:func:`beltjax.drive.pivot.friction_moment`; N m), which needs the arm's acceleration
    without it and its effective inertia: both from the drive's own solve, which is affine in the
    moment (one forward tangent gives M_ii^-1 g, g the arm's row of the kinematic map)."""

    name: ClassVar[str] = "tensioner_friction"

    def accelerations(self, acc, qi, qi_dot, scene, inst, t):
        # steady states (t None: the arm at rest) take no friction moment: the arm may rest
        # anywhere inside its friction band, and the operating point is the frictionless one
        if scene.tensioner is None or t is None:
            return acc
        from beltjax.drive.kinematics import angles_and_arm, arm_row

        g = arm_row(qi, scene, inst)  # a moment's generalised force on the arm
        omega = g @ qi_dot

        def with_friction(Q):
            # the accelerations are affine in the friction moment m: q'' = q''_0 + m c, with
            # c = M_ii^-1 g from the same solve (one forward tangent)
            out, d = jax.jvp(lambda m: acc(m * g if Q is None else Q + m * g), (jnp.zeros_like(omega),),
                             (jnp.ones_like(omega),))
            a0, c = (out[0], d[0]) if isinstance(out, tuple) else (out, d)
            m = pivot.friction_moment(omega, angles_and_arm(qi, scene, inst)[1], g @ a0, g @ c, scene.tensioner)
            return jax.tree_util.tree_map(lambda x, dx: x + m * dx, out, d)

        return with_friction


class BeltSlip(Effect):
    """Creep and gross slip on every wrapped arc: its slip states ride in the transient's state
    and slide the spans' end nodes in the kinematic map (:mod:`beltjax.drive.belt_slip`), and the
    operating point holds the running belt's arcs (:func:`beltjax.statics.equilibrium`); it
    contributes no potential or force of its own."""

    name: ClassVar[str] = "belt_slip"


class Unbalance(Effect):
    """Pulley centres of mass off the axis by cm_offset (m, in the pulley's frame): a pulley's
    body position is the centre of mass of the pulley and its wrapped belt (on the axis)."""

    name: ClassVar[str] = "unbalance"


    def body_positions(self, pos, angle, scene, inst):
        m_arc = scene.belt.rhoA * inst.radii * inst.wrap / inst.stretch  # wrapped belt (kg)
        out = []
        for i, name in enumerate(scene.route.order):
            if name == TENSIONER:
                out.append(pos[i])
                continue
            p = scene.pulley(name)
            e = p.cm_offset * p.mass / (p.mass + m_arc[i])
            c, sn = jnp.cos(angle[i]), jnp.sin(angle[i])
            out.append(pos[i] + jnp.stack([c * e[0] - sn * e[1], sn * e[0] + c * e[1]]))
        return jnp.stack(out)


class SpeedFluctuation(Effect):
    """The drive pulley's angle fluctuation: its harmonic A sin(2 pi f t) (fluctuation_amplitude_deg,
    fluctuation_frequency_hz) and the scene's [[fluctuation]] orders and frequencies
    (:class:`beltjax.scene.spec.Fluctuation`: orders follow the mean rotation)."""

    name: ClassVar[str] = "speed_fluctuation"

    def drive_angle(self, angle, pulley, t, scene, speed_rpm):
        A = jnp.deg2rad(pulley.fluctuation_amplitude_deg)
        out = A * jnp.sin(2 * jnp.pi * pulley.fluctuation_frequency_hz * t)
        for x in scene.fluctuations:
            if x.pulley == pulley.name:
                out = out + x.angle(angle, t, speed_rpm)
        return out


#: every effect module, by the name a scene lists
MODULES: dict[str, type[Effect]] = {m.name: m for m in (Transport, Gravity, BeltDamping, BearingDamping,
                                                          TensionerDamping, Unbalance, SpeedFluctuation,
                                                          TensionerFriction, BeltSlip)}
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

    def steady_body_forces(self, f, masses, scene, inst, transient: bool):
        """``f`` plus the listed effects' conservative forces on the bodies (N, N m)."""
        for x in self.listed:
            f = x.steady_body_forces(f, masses, scene, inst, transient)
        return f

    def body_positions(self, pos, angle, scene, inst):
        """The route entries' body positions (n, 2) m with the listed effects."""
        for x in self.listed:
            pos = x.body_positions(pos, angle, scene, inst)
        return pos

    def drive_angle(self, angle, pulley, t, scene, speed_rpm):
        """The drive pulley's angle (rad) at time t with the listed effects (``angle``: its mean
        rotation, rad; ``speed_rpm``: its nominal speed then, rpm)."""
        out = angle
        for x in self.listed:
            d = x.drive_angle(angle, pulley, t, scene, speed_rpm)
            out = out if d is None else out + d
        return out

    def accelerations(self, acc, qi, qi_dot, scene, inst, t):
        """q_i'' (rad/s^2, m/s^2; with slip states, (q_i'', their rates m/s)) of a transient at
        time t (s; None: a steady state) from ``acc``, the drive's accelerations as a function of
        added generalised forces Q (n_i,) or None, with the listed effects that act through them."""
        for x in self.listed:
            acc = x.accelerations(acc, qi, qi_dot, scene, inst, t)
        return acc(None)

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
