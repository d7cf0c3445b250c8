"""The moments on the tensioner arm at its pivot (N m, counter-clockwise positive), each law in
one place: the spring with its preload, the end stops, and dry friction.

- **Spring**: -k (theta - theta_0), k ``spring_stiffness`` (N m/rad), theta_0
  ``spring_preload_deg`` (the free angle).
- **End stops** (``stop_min_deg`` / ``stop_max_deg``, either or both): stiff contacts,
  -k_s (theta - theta_max) beyond the upper stop and k_s (theta_min - theta) below the lower
  one, k_s ``stop_stiffness`` (N m/rad).  Conservative (a potential with a continuous first
  derivative), so the installation, the operating point and the modes see them too.  A scene
  without stops traces none of this.
- **Dry friction** (effect ``tensioner_friction``): Coulomb friction by a regularised switch
  model (Karnopp 1985; Leine et al. 1998): the friction moment is whatever holds the arm, as
  long as it lies inside the friction band, and the band's edge while the arm slides,

      M_f = clip(-(theta''_0 + omega / tau) J_eff, lo(omega), hi(omega)),
      band at rest [-(T_f + D s), T_f - D s], s = sign(theta - theta_0), D = T_f (a - 1) / (a + 1),

  theta''_0 the arm's acceleration without the friction and J_eff its effective inertia (both
  from the drive's own solve: :meth:`beltjax.drive.effects.TensionerFriction.accelerations`).
  T_f ``friction_moment`` (N m, the mean band: the half-width of the torque-angle loop that
  ``beltjax fit`` identifies), a ``friction_asymmetry`` (the moment while the arm winds the
  spring up, i.e. the belt pushes it away from its free angle, over the moment while the spring
  returns it: T_f 2a / (1 + a) against T_f 2 / (1 + a)), tau ``friction_stick_time`` (s: a
  stuck arm's speed decays to zero at the rate 1 / tau instead of stopping at once), omega_r
  ``friction_speed`` (rad/s: the band closes to the sliding moment as the arm's speed passes
  omega_r: 58 % closed at omega_r, 99 % at 3 omega_r).  Below about omega_r the open band lets a
  stopping arm be held back, so friction may do positive work on it, at most about the band times
  omega_r tau per stop (measured as part of the energy per cycle: tests, benchmarks).
  Why this form: the regularised Coulomb law it replaced, -T_f tanh(omega / omega_r), has a
  viscous slope T_f / omega_r at rest that makes the equations stiff wherever the arm sticks
  (an explicit solver then needs thousands of steps per simulated second at any tolerance) and
  lets a stuck arm creep; this law's only fast rate is 1 / tau, it does not creep, and it has no
  state of its own (a bristle or LuGre model adds one per contact and a pre-sliding stiffness
  nobody measures on tensioners; Dahl's law, tried, was no cheaper: benchmarks/README.md
  section 5g).  Its edges are softened (softplus over 1e-3 of the band), so it is smooth for
  gradients.  What tau and omega_r change is measured in tests/test_tensioner_friction.py (Den
  Hartog's exact Coulomb oscillator) and benchmarks/bench_tensioner_friction.py.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp


def spring_moment(theta, t):
    """Moment of the tensioner spring on the arm (N m): -k (theta - theta_0), theta in rad."""
    return -t.spring_stiffness * (theta - jnp.deg2rad(t.spring_preload_deg))


def stop_moment(theta, t):
    """Moment of the end stops on the arm (N m) at arm angle theta (rad); 0 between them (and
    a plain 0.0 when the tensioner has no stops)."""
    m = 0.0
    if t.stop_max_deg is not None:
        m = m - t.stop_stiffness * jnp.maximum(theta - jnp.deg2rad(t.stop_max_deg), 0.0)
    if t.stop_min_deg is not None:
        m = m + t.stop_stiffness * jnp.maximum(jnp.deg2rad(t.stop_min_deg) - theta, 0.0)
    return m


def stop_pressed(t, angle_deg: float) -> tuple[str, float] | None:
    """(key, stop angle in deg) of the end stop an arm at ``angle_deg`` (deg, a number) is pressed
    into, beyond it, where :func:`stop_moment` acts; None between the stops (or without any)."""
    for key, stop, beyond in (("stop_max_deg", t.stop_max_deg, lambda s: angle_deg > s),
                              ("stop_min_deg", t.stop_min_deg, lambda s: angle_deg < s)):
        if stop is not None and beyond(float(stop)):
            return key, float(stop)
    return None


def elastic_moment(theta, t):
    """The arm's conservative pivot moment (N m): spring and end stops."""
    return spring_moment(theta, t) + stop_moment(theta, t)


def friction_moment(omega, theta, accel0, compliance, t):
    """Dry-friction moment on the arm (N m) at arm speed omega (rad/s) and angle theta (rad),
    given the arm's acceleration without it, accel0 (rad/s^2), and its compliance (rad/s^2 per
    N m: the arm's row of M_ii^-1, 1 / its effective inertia): a regularised switch model.

    The moment is the one that makes the arm's acceleration -omega / tau (tau
    ``friction_stick_time``, s: a stuck arm's speed decays to zero at the rate 1 / tau), held inside the friction band: [-(T_f + D s),
    T_f - D s] at rest (s = sign(theta - theta_0)), narrowing to the sliding moment -(T_f + D s)
    for omega >> omega_r and T_f - D s for omega << -omega_r (the band's far edge moves by
    tanh^2(omega / omega_r): 99 % closed at 3 omega_r, so friction opposes a sliding arm's motion
    once it slides faster than that).  The band's edges are
    softened over 1e-3 of its width (softplus), so the moment is smooth.
    """
    a = t.friction_asymmetry
    D = t.friction_moment * (a - 1.0) / (a + 1.0)
    loading = jnp.sign(theta - jnp.deg2rad(t.spring_preload_deg))
    up = t.friction_moment + D * loading    # resisting omega > 0
    down = t.friction_moment - D * loading  # resisting omega < 0
    band = up + down

    def closing(x):  # 0 at rest and against the motion, -> 1 when sliding
        return jnp.where(x > 0, jnp.tanh(x) ** 2, 0.0)

    hi = down - band * closing(omega / t.friction_speed)
    lo = -up + band * closing(-omega / t.friction_speed)
    needed = -(accel0 + omega / t.friction_stick_time) / compliance
    w = jnp.maximum(1e-3 * band, 1e-12)
    soft = lambda x: w * jax.nn.softplus(x / w)  # noqa: E731
    return lo + soft(needed - lo) - soft(needed - hi)


def coulomb_oscillator(P, k, m, w, phi, t):
    """y' = f(time, y, args) of the forced Coulomb oscillator m x'' + k x = P cos(w time + phi) + M_f
    with this module's friction law (``t``: the friction parameters, as a tensioner's), y = (x,
    x', the friction's work done on it so far): the reference problem of :func:`den_hartog`."""
    def f(time, y, args):
        x, v, _ = y
        a0 = (P * jnp.cos(w * time + phi) - k * x) / m  # the acceleration without friction
        fr = friction_moment(v, x, a0, 1.0 / m, t)
        return jnp.stack([v, a0 + fr / m, -fr * v])

    return f


def den_hartog(P, F, k, m, w):
    """The exact steady state of a Coulomb-damped oscillator m x'' + k x + F sgn(x') = P cos(w t
    + phi) without stops (Den Hartog 1930), the reference for the friction law: (X0 amplitude in
    the units of P / k, phi rad) with x = X0, x' = 0 at t = 0.  With r = w / w_n and G = P / (k - m w^2):
    X0 = sqrt(G^2 - (F / k)^2 tan^2(pi / 2r) / r^2), G cos(phi) = X0, G sin(phi) = -(F / k) tan(pi / 2r) / r."""
    r = w / math.sqrt(k / m)
    G = P / (k - m * w * w)
    v = -(F / k) * math.tan(math.pi / (2 * r)) / r
    X0 = math.sqrt(G * G - v * v)
    return abs(X0), math.atan2(v / G, X0 / G)
