"""Full mass matrix and forces in full coordinates: the span component's forces (ANCF spans or
massless bars, from their energies), the bodies' forces, loads and the layout's (a tensioner's
spring); only the effects the scene lists are traced.  Units: N, N m, kg, kg m^2."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from beltjax.scene import ARM, TENSIONER, Scene
from beltjax.drive.topology import GRAVITY, Installation, drive_pulley, element_length, span_names, travel_follows_drive
from beltjax.drive.effects import effects_of
from beltjax.drive.layouts import layout_of, spring_moment  # noqa: F401
from beltjax.drive.spans import bar_axial_force as _bar_axial_force, spans_of
from beltjax.drive.kinematics import split_full


def body_masses(scene: Scene, inst: Installation | None = None):
    """Diagonal of the bodies' mass matrix: (m, m, J) per body (kg, kg, kg m^2).

    With ``inst``, each pulley also carries the belt wrapped round it (no slip):
    mass rhoA R wrap / lam and inertia that times R^2 (the arc's centre of mass is
    taken at the pulley centre).
    """
    vals = []
    for name in scene.route.order:
        if name == TENSIONER:
            t = scene.tensioner
            vals.append(jnp.stack([t.pulley_mass, t.pulley_mass, t.pulley_inertia]))
        else:
            p = scene.pulley(name)
            vals.append(jnp.stack([p.mass, p.mass, p.inertia]))
    if inst is not None:
        m_arc = scene.belt.rhoA * inst.radii * inst.wrap / inst.stretch
        vals = [v + jnp.stack([m, m, m * R**2]) for v, m, R in zip(vals, m_arc, inst.radii)]
    return jnp.concatenate(vals + layout_of(scene).masses(scene))


def full_mass_matrix(scene: Scene, inst: Installation):
    """Block-diagonal mass matrix of the full coordinates (kg, kg m^2)."""
    model = spans_of(scene)
    Le = element_length(scene, inst)
    blocks = [model.mass_block(scene.belt.rhoA, Le[s]) for s in range(len(scene.route.order))]
    blocks.append(jnp.diag(body_masses(scene, inst)))
    return jax.scipy.linalg.block_diag(*blocks)


def span_potential(e, s: int, scene: Scene, inst: Installation, c=0.0):
    """Potential energy of span ``s`` (J) at its coordinates e: elastic plus the listed effects'
    (the span component's, :func:`beltjax.drive.spans.spans_of`); c: transport speed (m/s)."""
    return spans_of(scene).potential(e, scene.belt, element_length(scene, inst)[s], c, effects_of(scene))


def span_forces(e, e_dot, s: int, scene: Scene, inst: Installation, c=0.0, c_dot=0.0, dissipative=False):
    """Forces on the coordinates of span ``s`` (N): elastic, plus the listed effects.

    e, e_dot: the span's coordinates and rates; c: transport speed (m/s of
    unstretched belt), c_dot its rate (m/s^2).  ``transport`` adds the
    gyroscopic, centrifugal and rhoA dc/dt terms, ``gravity`` the weight;
    with ``dissipative`` (transients) ``belt_damping`` adds the viscous axial
    force of CA (N s): Rayleigh function 1/2 int CA (d eps/dt)^2 dx.  The span component
    (ANCF span or bar) computes them.
    """
    Le = element_length(scene, inst)[s]
    return spans_of(scene).forces(e, e_dot, scene.belt, Le, c, c_dot, effects_of(scene), dissipative)


def bar_axial_force(length, rate, L0, scene: Scene, c=0.0):
    """:func:`beltjax.drive.spans.bar_axial_force` of the scene's belt (N)."""
    return _bar_axial_force(length, rate, L0, scene.belt, c)


def body_forces(bodies, scene: Scene, inst: Installation | None = None, bodies_dot=None, t=None):
    """Applied forces on the bodies (nb, 3): spring moment on the arm, weights (N, N m).

    With a time ``t`` (s; transients) and the bodies' rates ``bodies_dot``: the listed
    damping effects (bearing: -c_b times the pulley's absolute speed; tensioner: -c
    times the arm's speed, N m s/rad) and the [[torque]] loads (N m).
    """
    f = layout_of(scene).body_forces(jnp.zeros_like(bodies), bodies, scene)
    fx = effects_of(scene)
    if "gravity" in fx:
        f = f.at[:, 1].add(GRAVITY[1] * body_masses(scene, inst).reshape(-1, 3)[:, 0])
        if inst is not None and spans_of(scene).massive:  # the belt's weight on its spans
            f = f.at[: len(scene.route.order), 2].add(_belt_weight_slide_moments(scene, inst, t is not None))
    if t is None:
        return f
    order = scene.route.order
    f = fx.body_forces(f, bodies, bodies_dot, scene, t)
    for load in scene.torques:
        k = -1 if load.pulley == ARM else order.index(load.pulley)
        f = f.at[k, 2].add(torque(load, t))
    return f


def _belt_weight_slide_moments(scene: Scene, inst: Installation, transient: bool = False):
    """Moments (N m) on the pulleys that make a rigid turn of the belt loop cost no weight.

    A pulley's rotation perturbation slides the span end nodes along their spans (s R phi);
    the belt itself flows through the spans, so sliding a span along its own line must not
    move its weight.  The span's weight is counted with its nodes shifted back by the
    interpolated end slides, (1 - x) s0 + x s1 along the span: that adds the potential
    rhoA (g . t) L0 (s0 + s1) / 2 per span, i.e. these constant moments (a pure moment: the
    bearing forces are unchanged).  In a transient whose belt travels with a free drive
    pulley (:func:`travel_follows_drive`) the slides are taken relative to that travel,
    s R phi - s_d R_d phi_d, which adds to the drive pulley's moment minus s_d R_d times the
    others' sum of m_i / (s_i R_i): a rigid turn of the loop, which then moves no node, does no
    work either.
    """
    n = len(scene.route.order)
    g = jnp.asarray(GRAVITY)
    L0 = element_length(scene, inst) * spans_of(scene).elements
    senses = jnp.asarray(scene.route.senses, dtype=L0.dtype)
    w = scene.belt.rhoA * (inst.span_tangent @ g) * L0 / 2  # per span, N
    prev = (np.arange(n) - 1) % n
    m = -(w + w[prev]) * senses * inst.radii
    if transient and travel_follows_drive(scene):
        d = drive_pulley(scene)
        m = m.at[d].add(-senses[d] * inst.radii[d] * jnp.sum(m / (senses * inst.radii)))
    return m


def _window(t, t_start, t_end):
    on = t >= t_start
    if t_end is not None:
        on = on & (t < t_end)
    return jnp.where(on, 1.0, 0.0)


def torque(load, t):
    """Moment of a [[torque]] load at time t (N m, CCW positive)."""
    w = 2 * jnp.pi * load.frequency_hz * t + jnp.deg2rad(load.phase_deg)
    return _window(t, load.t_start_s, load.t_end_s) * (load.mean_Nm + load.amplitude_Nm * jnp.sin(w))


def span_load_force(load, t):
    """Magnitude of a [[span_load]] force at time t (N), normal to the installed span."""
    w = 2 * jnp.pi * load.frequency_hz * t + jnp.deg2rad(load.phase_deg)
    return _window(t, load.t_start_s, load.t_end_s) * load.amplitude_N * jnp.sin(w)


def full_forces(q, q_dot, scene: Scene, inst: Installation, c=0.0, c_dot=0.0, t=None):
    """Forces on all full coordinates (N, N m) for the listed effects.

    t: time (s) for transients: adds the dissipative effects and the loads; None gives the
    conservative steady forces of statics and modal analysis.
    """
    E, B = split_full(q, scene)
    Ed, Bd = split_full(q_dot, scene)
    dyn = t is not None
    fs = [span_forces(E[s], Ed[s], s, scene, inst, c, c_dot, dissipative=dyn) for s in range(E.shape[0])]
    if dyn and scene.span_loads:
        names = span_names(scene)
        for load in scene.span_loads:
            s = names.index(load.span)
            tan = inst.span_tangent[s]
            normal = jnp.stack([-tan[1], tan[0]])
            fs[s] = fs[s].at[4 * load.node : 4 * load.node + 2].add(span_load_force(load, t) * normal)
    return jnp.concatenate(fs + [body_forces(B, scene, inst, Bd, t).reshape(-1)])
