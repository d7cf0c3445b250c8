"""Full mass matrix and forces in full coordinates: the span component's forces (ANCF spans or
massless bars, from their energies), the bodies' forces, loads and the layout's (a tensioner's
spring); only the effects the scene lists are traced.  Units: N, N m, kg, kg m^2."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from beltjax.scene import ARM, TENSIONER, Scene
from beltjax.drive.topology import Installation, body_names, element_length, span_names
from beltjax.drive import couplings
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
    rotors = [jnp.stack([0.0 * d.rotor_inertia, 0.0 * d.rotor_inertia, d.rotor_inertia]) for d in scene.decouplers]
    return jnp.concatenate(vals + rotors + layout_of(scene).masses(scene))


def span_mass_blocks(scene: Scene, inst: Installation):
    """The spans' blocks of the full mass matrix, (n spans, 4 (N+1), 4 (N+1)) (kg)."""
    model = spans_of(scene)
    Le = element_length(scene, inst)
    blocks = jax.vmap(lambda le: model.mass_block(scene.belt.rhoA, le))(Le)
    n, P = Le.shape[0], 4 * (model.elements + 1)
    return jnp.broadcast_to(blocks, (n, P, P))


def full_mass_matrix(scene: Scene, inst: Installation):
    """Block-diagonal mass matrix of the full coordinates (kg, kg m^2): the spans' blocks
    (:func:`span_mass_blocks`), then the bodies' diagonal (:func:`body_masses`)."""
    return jax.scipy.linalg.block_diag(*span_mass_blocks(scene, inst), jnp.diag(body_masses(scene, inst)))


def span_potential(e, s: int, scene: Scene, inst: Installation, c=0.0):
    """Potential energy of span ``s`` (J) at its coordinates e: elastic plus the listed effects'
    (the span component's, :func:`beltjax.drive.spans.spans_of`); c: transport speed (m/s)."""
    return spans_of(scene).potential(e, scene.belt, element_length(scene, inst)[s], c, effects_of(scene))


def span_forces(e, e_dot, s: int, scene: Scene, inst: Installation, c=0.0, c_dot=0.0, dissipative=False):
    """Forces on the coordinates of span ``s`` (N; ``s`` an int or a traced index, to map over
    the spans): elastic, plus the listed effects.

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
    f = couplings.body_forces(f, bodies, scene, engaged=t is None)  # decouplers (engaged in statics)
    fx = effects_of(scene)
    f = fx.steady_body_forces(f, body_masses(scene, inst).reshape(-1, 3), scene, inst, t is not None)  # weights
    if t is None:
        return couplings.isolator_forces(f, bodies, None, scene)
    f = couplings.isolator_forces(f, bodies, bodies_dot, scene, t)
    f = fx.body_forces(f, bodies, bodies_dot, scene, t)
    if scene.decouplers:
        f = couplings.damping_forces(f, bodies, bodies_dot, scene)
    if scene.torques:  # one scatter for all loads (one kernel, not one per load)
        rows = np.array([_load_row(scene, load.pulley) for load in scene.torques]) % f.shape[0]
        f = f.at[rows, 2].add(jnp.stack([torque(load, t) for load in scene.torques]))
    return f


def _load_row(scene: Scene, name: str) -> int:
    """The body row a [[torque]] on ``name`` acts on: the arm (last), a decoupled pulley's
    rotor, else the pulley."""
    if name == ARM:
        return -1
    r = couplings.load_body(scene, name)
    return scene.route.order.index(name) if r is None else r


def mean_body_loads(scene: Scene, inst: Installation, speed=0.0):
    """The steady loads of the operating point on the bodies, (nb, 3) (N, N, N m).

    Each lasting [[torque]] load's mean_Nm (one without ``t_end_s``: a pulse that ends is no
    part of the steady state; the harmonic part averages out), and the listed effects' body
    forces at the steady motion of belt speed ``speed`` (m/s): every pulley turning at its
    rolling speed s v / R (rad/s), the arm at rest (bearing damping: a drag -c_b s v / R).
    """
    order = scene.route.order
    nb = len(body_names(scene))
    f = jnp.zeros((nb, 3), dtype=inst.radii.dtype)
    for load in scene.torques:
        if load.t_end_s is None:
            f = f.at[_load_row(scene, load.pulley), 2].add(load.mean_Nm)
    senses = jnp.asarray(scene.route.senses, dtype=f.dtype)
    rates = jnp.zeros_like(f).at[: len(order), 2].set(senses * speed / inst.radii)
    return effects_of(scene).body_forces(f, None, rates, scene, None)


def lasting_loads(scene: Scene) -> bool:
    """Whether the scene's structure has loads that last (a [[torque]] without ``t_end_s``, or
    listed bearing damping): whatever their values, its operating point is solved for them."""
    return any(load.t_end_s is None for load in scene.torques) or "bearing_damping" in effects_of(scene)


def has_mean_loads(scene: Scene) -> bool:
    """Whether the scene's operating point differs from its unloaded state: a lasting [[torque]]
    with a mean, or listed bearing damping."""
    lasting = any(load.t_end_s is None and float(load.mean_Nm) != 0.0 for load in scene.torques)
    drag = "bearing_damping" in effects_of(scene) and any(float(p.bearing_damping) > 0 for p in scene.pulleys)
    return lasting or drag


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
    model, fx = spans_of(scene), effects_of(scene)
    # every span at once (one traced program, whatever the number of spans; they differ only in Le)
    fs = jax.vmap(lambda e, ed, le: model.forces(e, ed, scene.belt, le, c, c_dot, fx, dyn))(
        E, Ed, element_length(scene, inst))
    if dyn and scene.span_loads:
        names = span_names(scene)
        for load in scene.span_loads:
            s = names.index(load.span)
            tan = inst.span_tangent[s]
            normal = jnp.stack([-tan[1], tan[0]])
            fs = fs.at[s, 4 * load.node : 4 * load.node + 2].add(span_load_force(load, t) * normal)
    return jnp.concatenate([fs.reshape(-1), body_forces(B, scene, inst, Bd, t).reshape(-1)])
