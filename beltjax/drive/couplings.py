"""Bodies joined to a pulley rather than to the belt: the decoupler's rotor; and the crank
isolator, which joins the crank's rim to its prescribed hub.

An overrunning alternator decoupler (:class:`beltjax.scene.spec.Decoupler`) is the pulley, a
spring and a one-way clutch in series with the rotor.  The rotor is a body of its own (one
rotation coordinate, its inertia ``rotor_inertia``; it shares the pulley's bearing and centre).
The spring carries the pulley's lead over the rotor in the belt's direction of travel,

    M = k max(w, 0),   w = s (theta_pulley - theta_rotor)   (s the pulley's wrap sense),

on the rotor (driving it on) and -M on the pulley; when the rotor is ahead (w < 0) the clutch
overruns and nothing is transmitted.  The law is the derivative of the potential k max(w, 0)^2 / 2,
continuous with its first derivative (C1), so statics, modes and gradients see it; at w = 0 the
spring counts as engaged (a clutch at rest locks on any lead): the modes of an unloaded
decoupler are those of the engaged one.  Statics and the modes about it take the engaged spring
on both sides of w = 0 (``engaged``): a steadily turning rotor is carried by its spring, so its
wind-up is its mean load over k, and an unloaded rotor (a decoupler on an idler) sits at w = 0
instead of anywhere in the overrunning range, where its angle would have no equilibrium (Newton
met a singular matrix there); a load that drives the rotor ahead (w < 0) has no steady state and
the statics says so (:mod:`beltjax.static_state`).  In transients a viscous ``damping`` acts across the
spring while the clutch is engaged.  The clutch's own drag is not modelled.  A scene without
decouplers traces none of this.

A crank isolator (:class:`beltjax.scene.spec.Isolator`) makes the driven crank's rim a free
body (its rotation a coordinate: the belt's travel follows it) on a spring and damper to the
hub, whose angle theta_h(t) is the crank's prescribed motion (speed, run-up, fluctuation):
M = -k (theta - theta_h) - c (theta' - theta_h') on the rim.  In statics the rim is held at
the hub (theta = theta_h) and the drive torque is what the spring carries, so the wind-up at
the operating point is -(drive torque) / k.
"""

from __future__ import annotations

import jax.numpy as jnp

from beltjax.scene.spec import Scene


def rotor_routes(scene: Scene) -> tuple[int, ...]:
    """Route index of each decoupled pulley, in the order of ``scene.decouplers`` (its rotor's)."""
    return tuple(scene.route.order.index(d.pulley) for d in scene.decouplers)


def decoupler_moment(windup, stiffness):
    """The decoupler spring's moment (N m) at wind-up ``windup`` (rad, the pulley's lead over
    the rotor in the direction of travel): k w when w >= 0, else 0 (the clutch overruns)."""
    return jnp.where(windup >= 0.0, stiffness * windup, 0.0)


def windups(pulley_angles, rotor_angles, scene: Scene):
    """Each decoupler's wind-up (rad): its pulley's lead over its rotor in the belt's direction of
    travel, s (phi_pulley - psi_rotor), from the route entries' angles (n,) and the rotors' (k,)
    (rad; or their rates, rad/s, for the wind-up's rate).  Shape (k,), ``scene.decouplers`` order."""
    routes = jnp.asarray(rotor_routes(scene), dtype=int)
    senses = jnp.asarray([float(scene.route.senses[i]) for i in rotor_routes(scene)])
    return senses * (pulley_angles[routes] - rotor_angles)


def _apply(f, moments, scene: Scene):
    """``f`` plus each decoupler's moment M (k,) (N m): -s M on its pulley, +s M on its rotor."""
    n = len(scene.route.order)
    for j, i in enumerate(rotor_routes(scene)):
        s = float(scene.route.senses[i])
        f = f.at[i, 2].add(-s * moments[j]).at[n + j, 2].add(s * moments[j])
    return f


def body_forces(f, bodies, scene: Scene, engaged: bool = False):
    """``f`` (nb, 3; N, N m) plus the decouplers' moments on their pulleys and rotors; bodies
    (nb, 3): the bodies' (x, y, angle), the rotors right after the route entries.  ``engaged``
    (statics and its modes): the spring k w on both sides of w = 0 (see the module docstring)."""
    if not scene.decouplers:
        return f
    n = len(scene.route.order)
    w = windups(bodies[:n, 2], bodies[n : n + len(scene.decouplers), 2], scene)
    k = jnp.stack([d.stiffness for d in scene.decouplers])
    return _apply(f, k * w if engaged else decoupler_moment(w, k), scene)


#: a static wind-up below this (rad) means the mean load drives the rotor ahead: the clutch overruns
OVERRUN_WINDUP = -1e-9


def static_windups(qi, scene: Scene, inst):
    """Each decoupler's wind-up (rad, ``scene.decouplers`` order) at the static state ``qi``; an
    entry below :data:`OVERRUN_WINDUP` is a load that drives the rotor ahead, which has no steady
    state (statics takes the spring engaged on both sides of zero: see the module docstring)."""
    from beltjax.drive.kinematics import angles_and_arm, rotor_angles

    phis, _ = angles_and_arm(qi, scene, inst)
    return windups(phis, rotor_angles(qi, scene), scene)


def static_overrun(qi, scene: Scene, inst):
    """Whether a decoupler's mean load drives its rotor ahead at the static state ``qi`` (bool;
    False without decouplers): the batched statics' check (sweeps, optimisation)."""
    if not scene.decouplers:
        return jnp.asarray(False)
    return jnp.any(static_windups(qi, scene, inst) < OVERRUN_WINDUP)


def damping_forces(f, bodies, bodies_dot, scene: Scene):
    """``f`` plus the decouplers' viscous moments (transients): c times the rate of wind-up while
    the clutch is engaged (w >= 0), nothing while it overruns (N m)."""
    n, k = len(scene.route.order), len(scene.decouplers)
    w = windups(bodies[:n, 2], bodies[n : n + k, 2], scene)
    rate = windups(bodies_dot[:n, 2], bodies_dot[n : n + k, 2], scene)
    c = jnp.stack([d.damping for d in scene.decouplers])
    return _apply(f, jnp.where(w >= 0.0, c * rate, 0.0), scene)


def load_body(scene: Scene, name: str) -> int | None:
    """The body row a [[torque]] on ``name`` acts on: a decoupled pulley's rotor, else None (the
    pulley's own row, or the arm's)."""
    for j, d in enumerate(scene.decouplers):
        if d.pulley == name:
            return len(scene.route.order) + j
    return None


def hub_angle(scene: Scene, t):
    """The isolated crank's hub angle (rad, CCW) and speed (rad/s) at time t: its prescribed motion."""
    import jax

    from beltjax.drive.kinematics import belt_travel

    i = scene.route.order.index(scene.isolator.pulley)
    k = float(scene.route.senses[i]) / scene.pulley(scene.isolator.pulley).radius
    x, v = jax.jvp(lambda tt: belt_travel(scene, tt), (t,), (jnp.ones_like(t),))
    return k * x, k * v


def isolator_moment(scene: Scene, angle, rate, t=None):
    """The isolator's moment on the crank's rim (N m) at rim angle ``angle`` (rad) and speed
    ``rate`` (rad/s): -k (angle - hub) - c (rate - hub rate); t None (statics): the hub at rest
    at 0 and no damping."""
    iso = scene.isolator
    if t is None:
        return -iso.stiffness * angle
    h, hd = hub_angle(scene, t)
    return -iso.stiffness * (angle - h) - iso.damping * (rate - hd)


def isolator_forces(f, bodies, bodies_dot, scene: Scene, t=None):
    """``f`` plus the isolator's moment on the crank's rim (nothing without an isolator)."""
    if scene.isolator is None:
        return f
    i = scene.route.order.index(scene.isolator.pulley)
    rate = None if bodies_dot is None else bodies_dot[i, 2]
    return f.at[i, 2].add(isolator_moment(scene, bodies[i, 2], rate, t))


def isolator_lag(isolator, drive_torque):
    """How far (rad) an isolated crank's rim lags its hub in a steady motion: the drive torque
    (N m) over the isolator's stiffness, -M / k."""
    return -drive_torque / isolator.stiffness


def isolator_wind_up(scene: Scene, inst, qi, drive_torque):
    """q_i (m, rad) of the steady state ``qi`` with an isolated crank's rim lagging its hub by the drive
    torque (N m) over the isolator's stiffness: the belt loop turned by that lag (pure JAX; ``qi``
    unchanged without an isolator)."""
    if scene.isolator is None:
        return qi
    from beltjax import drive_modal

    d = scene.route.order.index(scene.isolator.pulley)  # the driven drive pulley
    lag = isolator_lag(scene.isolator, drive_torque)  # rad
    return qi + drive_modal.rigid_mode(scene, inst) * (scene.route.senses[d] * inst.radii[d] * lag)
