"""Belt creep and gross slip on every wrapped arc (effect ``belt_slip``, the rotational model).

Without this effect the belt sticks to every rim: each pulley's rim feeds its exit span and
drains its entry span at its own speed, so every rim runs at the belt's speed and an arc
carries any tension ratio, and each arc holds the belt it held when the run started.  With it,
each route entry i has three slip states (m, along the belt in its direction of travel,
relative to the rim):

- ``g_i``, gross slip: how far the belt on the arc has slid over the rim as a whole;
- ``u_i``, creep: how much more belt has left the arc into its exit span than the rim carried;
- ``d_i``, the arc's exchange: how much more belt the arc has handed its exit span than at the
  start (beyond ``inst.creep``, the running belt's at the operating point).

The kinematic map (:func:`beltjax.drive.kinematics.full_coordinates`) slides span i's start
node (the exit of entry i) by ``g_i + u_i + d_i`` and its end node (the entry of entry i + 1) by
``g_{i+1}``, so every span's length, tension and force on the pulleys, and through them the
pulleys' torques, follow the slip; nothing else changes.  Their rates:

- **creep** (classical creep theory, Reynolds/Grashof): the belt adheres where it runs on and
  creeps over the arc to its exit, where it leaves with the exit span's stretch:
  ``u_i' = max(v_i + g_i', 0) (lam_out / lam_in - 1)``, v_i the rim speed (m/s; plus the gross
  slip, the belt's speed where it runs on), lam the spans' stretches l / L0.  A steady drive then turns each pulley at
  ``v_{i+1} = v_i lam_i / lam_{i-1}`` (driven pulleys slower than the radius ratio says) and
  dissipates ``sum_i F_i u_i'``: the creep loss (F the exit span's force).  No regularisation:
  this is a smooth rate.  A rim turning backwards (v < 0) creeps nothing (a reversed belt's
  entry and exit swap; not modelled);
- **gross slip** (the capstan law, regularised): the arc transmits a force difference
  ``dF = F_in - F_out`` (the spans' forces on the pulleys, T - rhoA c^2 lam) up to its
  capacity ``C = F_min (exp(mu' theta) - 1)`` (Euler-Eytelwein: mu' the effective coefficient
  of :func:`beltjax.friction.effective_coefficients`, theta the present wrap), beyond which
  the belt slides over the whole arc: ``g_i' = -sign(dF) v_r r((|dF| - C) / C_0)``, r the ramp
  max(x, 0) rounded (C1) over 0.1 %, ``C_0 = T_0 (exp(mu' theta_0) - 1)`` the arc's capacity at
  the installation tension T_0 and the installed wrap theta_0.  The sliding arc transmits
  ``C + C_0 |g'| / v_r``: v_r
  (``belt.slip_speed``, m/s, default 100) is the regularisation, a linear rise of the friction
  force with the sliding speed that makes the law smooth and the slip state an ODE rather than a
  complementarity problem; the scale C_0 is fixed, so a span that goes slack (C -> 0) leaves the
  arc a finite, viscous grip rather than an infinitely stiff one.  What it changes is measured
  in tests/test_belt_slip.py and its cost in benchmarks/bench_belt_slip.py.  The friction power
  ``-dF g'`` is dissipated;
- **the arc's belt** (the running belt's compatibility, :func:`beltjax.friction.arc_belt_moved`):
  the belt on an arc is the belt that ran on there, so as the spans' tensions change the arc's
  belt is replaced over the time the belt takes to cross it, R theta / v.  ``d_i`` follows the
  belt the arc would hand its exit span at the present forces and stretches, D_i, with a
  first-order lag of the crossing's mean delay: ``d_i' = 2 |v_i| / (R_i theta_i) (D_i -
  inst.creep_i - d_i)`` (theta_i the present wrap).  A steady drive so ends in the statics'
  operating point (which solves D = inst.creep), and a drive at rest keeps its arcs.

Limits: the slip states are the rotational model's (the hybrid model's arcs are Eulerian
contacts without their own belt material): a hybrid scene with ``belt_slip`` takes the running
belt's operating point (statics, modes, Campbell diagrams, sweeps) and its transient is refused
(:func:`transient_check`); the arc's belt is replaced with a first-order lag, not the exact transport delay; the
friction law sees the spans' elastic forces (belt damping acts on their whole stretching rate,
the slip's included); the wrapped belt's inertia stays with its pulley (about 1 % of a small
pulley's) while it slides.  Units: SI.
"""

from __future__ import annotations

import jax.numpy as jnp

from beltjax import friction
from beltjax.drive.effects import effects_of
from beltjax.scene import Scene

#: the ramp's rounding, as a fraction of the installed capacity C_0 (a sliding arc carries at most
#: half of it beyond C + C_0 |g'| / v_r; it costs no steps: the slope stays below 1 / C_0)
ROUNDING = 1e-3


def running(scene: Scene) -> bool:
    """Whether ``scene``'s belt creeps (``belt_slip`` listed, either fidelity): its operating point
    holds the running belt's compatibility (:func:`beltjax.statics.equilibrium`)."""
    return "belt_slip" in effects_of(scene)


def n_states(scene: Scene) -> int:
    """Slip states of ``scene``'s transient: 3 per route entry with ``belt_slip`` listed, else 0
    (a hybrid transient with it is refused: :func:`transient_check`)."""
    return 3 * len(scene.route.order) if running(scene) else 0


def initial(scene: Scene, dtype=jnp.float64):
    """The slip states at the start of a transient: none has slid (m), shape (n_states,)."""
    return jnp.zeros(n_states(scene), dtype=dtype)


def split_state(y, n: int):
    """A transient's state -> (q_i, q_i', the slip states: empty without ``belt_slip``), for
    n = n_independent; y (..., 2 n + n_states)."""
    return y[..., :n], y[..., n:2 * n], y[..., 2 * n:]


def creep_start(scene: Scene, inst, qi, qd):
    """The free pulleys' (and their rotors') rotation rates q_i' (rad/s) of a steady creep from
    the state q_i: each rim runs at the speed of its entry span's belt, v_i = v lam_{i-1} /
    lam_{d-1} with v the drive pulley's rim speed (m/s, its mean) and d the drive pulley, so a
    transient with ``belt_slip`` starts in its steady creep rather than in a small transient to
    it.  Unchanged without ``belt_slip``, or when the drive pulley is turned by a torque."""
    from beltjax import drive

    if n_states(scene) == 0 or drive.travel_follows_drive(scene):
        return qd
    lam = drive.span_lengths(qi, scene, inst) / drive.element_length(scene, inst)
    d = drive.drive_pulley(scene)
    lam_in = jnp.roll(lam, 1)
    v = drive.belt_speed(scene) * (lam_in / lam_in[d] - 1.0)  # each rim's speed beyond the nominal rolling
    rate = v / (jnp.asarray(scene.route.senses, dtype=qi.dtype) * inst.radii)
    free = [i for i, f in enumerate(drive.is_free(scene)) if f]
    rows = free + list(drive.drive_of(scene).rotors)  # a rotor turns with its pulley
    return qd.at[: rotations(scene)].set(rate[jnp.asarray(rows, dtype=int)])


def rotations(scene: Scene) -> int:
    """How many of q_i's first coordinates are rotations that creep (rad): the free pulleys',
    then the decouplers' rotors' (:func:`beltjax.drive.kinematics.rotor_angles`)."""
    from beltjax import drive

    return sum(drive.is_free(scene)) + len(scene.decouplers)


def node_shifts(z, n: int):
    """How far each span's start and end node slide along it (m), each (n,), for slip states
    z = (g, u, d) (3n,) m (or their rates): start by g_i + u_i + d_i, end by g_{i+1}."""
    g, u, d = z[:n], z[n:2 * n], z[2 * n:]
    return g + u + d, jnp.roll(g, -1)


def length_offsets(z, n: int):
    """The slip's share of each span's length (m), (n,): end shift - start shift."""
    start, end = node_shifts(z, n)
    return end - start


def ramp(x, width=ROUNDING):
    """max(x, 0), rounded to C1 over x in [0, width] (-)."""
    inner = jnp.where(x > 0, x, 0.0) ** 2 / (2 * width)
    return jnp.where(x > width, x - 0.5 * width, inner)


def rates(forces, stretches, rim_speeds, scene: Scene, inst, wraps, z):
    """Slip rates (m/s) (g', u', d'), (3n,): forces (n,) N each span's force on the pulleys (span
    i leaves entry i), stretches (n,) the spans' l / L0, rim_speeds (n,) m/s along the belt's
    travel, inst the installation (its wraps (rad) and tension T_0 (N) set the capacities, its
    ``creep`` (m) the arcs' belt at the start), wraps (n,) rad the present wraps, z (3n,) m the
    slip states (see the module docstring)."""
    wrap, tension = inst.wrap, inst.tension
    n = forces.shape[0]
    mu = friction.effective_coefficients(scene)
    f_in = jnp.roll(forces, 1)
    d_f = f_in - forces
    gain = jnp.expm1(mu * wraps)  # exp(mu' theta) - 1 over the present wrap (an arm's swing turns it)
    capacity = jnp.maximum(jnp.minimum(forces, f_in), 0.0) * gain  # C: the smaller span force (floored at 0)
    scale = tension * jnp.expm1(mu * wrap)  # C_0 = T_0 (exp(mu' theta_0) - 1): installed, a fixed scale
    slide = scene.belt.slip_speed * ramp((jnp.abs(d_f) - capacity) / scale)
    g_dot = 0.0 - jnp.sign(d_f) * slide  # (no -0.0 where it holds)
    lam_in = jnp.roll(stretches, 1)
    u_dot = jnp.maximum(rim_speeds + g_dot, 0.0) * (stretches / lam_in - 1.0)
    held = friction.arc_belt_moved(forces, stretches, wraps, inst.radii, inst.stretch, mu)
    d_dot = 2.0 * jnp.abs(rim_speeds) / (inst.radii * wraps) * (held - inst.creep - z[2 * n:])
    return jnp.concatenate([g_dot, u_dot, d_dot])


def dissipation(forces, z_dot, n: int):
    """Friction power (W) of the slip rates z_dot (3n,) under span forces (n,) N: the gross
    slip's -dF g', the creep loss sum F_out u', and the power the spans hand the arcs' belt as it
    is replaced, sum F_out d' (the arcs' own elastic energy and the microslip that replaces their
    belt are not states: the power leaves the model's energy here; it averages out in a steady
    run, and is negative while the arcs give belt back)."""
    g_dot, u_dot, d_dot = z_dot[:n], z_dot[n:2 * n], z_dot[2 * n:]
    return jnp.sum(-(jnp.roll(forces, 1) - forces) * g_dot) + jnp.sum(forces * (u_dot + d_dot))


def transient_check(scene: Scene) -> tuple[str, str] | None:
    """(key, why) when a transient of ``scene`` cannot run ``belt_slip`` (the hybrid model's: its
    statics, modes and Campbell diagrams take the running belt's operating point), else None."""
    from beltjax.drive.spans import spans_of

    if running(scene) and spans_of(scene).massive:
        return ("model.effects", "belt_slip's creep and gross slip dynamics are built for the rotational model's "
                "transient (fidelity = \"rotational\"); the hybrid model takes its running operating point in "
                "statics, modes and Campbell diagrams only: drop belt_slip from this transient's effects")
    return None


def check(scene: Scene) -> tuple[str, str] | None:
    """(key, why) when ``scene`` cannot list ``belt_slip``, else None."""
    if not running(scene):
        return None
    given = set(friction.given(scene))
    missing = [name for i, name in enumerate(scene.route.order) if i not in given]
    if missing:
        return ("belt.friction_coefficient", "belt_slip needs a friction coefficient on every wrapped arc; none for "
                + ", ".join(repr(m) for m in missing))
    return None
