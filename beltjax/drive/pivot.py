"""The moments on the tensioner arm at its pivot (N m, counter-clockwise positive), each law in
one place: the spring with its preload, the end stops, and dry friction.

- **Spring**: -k (theta - theta_0), k ``spring_stiffness`` (N m/rad), theta_0
  ``spring_preload_deg`` (the free angle).
- **End stops** (``stop_min_deg`` / ``stop_max_deg``, either or both): stiff contacts,
  -k_s (theta - theta_max) beyond the upper stop and k_s (theta_min - theta) below the lower
  one, k_s ``stop_stiffness`` (N m/rad).  Conservative (a potential with a continuous first
  derivative), so the installation, the operating point and the modes see them too.  A scene
  without stops traces none of this.
- **Dry friction** (effect ``tensioner_friction``): regularised Coulomb,

      M_f(omega, theta) = -tanh(omega / omega_r) (T_f + D tanh(omega / omega_r) sign(theta - theta_0)),
      D = T_f (a - 1) / (a + 1),

  T_f ``friction_moment`` (N m, the mean band: the half-width of the torque-angle loop that
  ``beltjax fit`` identifies), a ``friction_asymmetry`` (the moment while the arm winds the
  spring up, i.e. the belt pushes it away from its free angle, over the moment while the spring
  returns it: T_f 2a / (1 + a) against T_f 2 / (1 + a)), omega_r ``friction_speed`` (rad/s).
  Why this form: it has no state of its own (a bristle or LuGre model adds one per contact and a
  pre-sliding stiffness that is a parameter nobody measures for tensioners; Dahl's bristle law,
  tried, came no closer to the Coulomb limit for the explicit solver's steps than a larger
  omega_r: benchmarks/README.md section 5g), it is smooth, so
  gradients and implicit solvers see a Jacobian, and it slides at every speed: a stuck arm
  creeps at the speed where tanh(omega / omega_r) T_f balances the net moment, which is below
  omega_r.  What the regularisation changes is measured in tests/test_tensioner_friction.py
  (Den Hartog's exact Coulomb oscillator) and stated in the README.
"""

from __future__ import annotations

import math

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


def elastic_moment(theta, t):
    """The arm's conservative pivot moment (N m): spring and end stops."""
    return spring_moment(theta, t) + stop_moment(theta, t)


def friction_moment(omega, theta, t):
    """Dry-friction moment on the arm (N m) at arm speed omega (rad/s) and angle theta (rad):
    regularised Coulomb, optionally asymmetric (see the module docstring)."""
    s = jnp.tanh(omega / t.friction_speed)
    a = t.friction_asymmetry
    D = t.friction_moment * (a - 1.0) / (a + 1.0)
    loading = jnp.sign(theta - jnp.deg2rad(t.spring_preload_deg))
    return -s * (t.friction_moment + D * s * loading)


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
