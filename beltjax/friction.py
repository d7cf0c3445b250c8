"""Belt-pulley friction at a steady state: the friction each wrapped arc needs, what it has, and
the slip margin (the capstan law).

On an arc of wrap angle theta (rad) a belt whose spans pull the pulley with forces F_in and
F_out (each span's tension less its centrifugal part, T - rhoA c^2 lam:
:func:`beltjax.critical.pulley_forces`) holds without gross slip while
``|ln(F_out / F_in)| <= mu' theta`` (Euler-Eytelwein, the centrifugal tension taken out), so the
arc needs the friction coefficient ``mu_needed = |ln(F_out / F_in)| / theta``.  The effective
coefficient ``mu'`` is the belt's ``friction_coefficient`` (or the pulley's own) for a flat belt
or a ribbed belt's flat back, and ``mu / sin(beta / 2)`` where the ribs of a V or ribbed belt
(``belt.groove_angle_deg`` = beta) run in the pulley's grooves: the wedge multiplies the normal
force.  The slip margin is ``1 - mu_needed / mu'``: 1 at no load, 0 at the capstan limit, below 0
the arc would slip.  The whole arc is then sliding (creep at the limit); the creep itself,
the speed it costs and a sliding belt's dynamics are not modelled here.  Units: SI, angles rad.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from beltjax.scene import TENSIONER, Scene


def effective_coefficients(scene: Scene):
    """Effective friction coefficient mu' (-) per route entry, NaN where the scene gives none
    (pure: differentiable in the coefficients and the groove angle)."""
    b = scene.belt
    out = []
    for name in scene.route.order:
        mu = None if name == TENSIONER else scene.pulley(name).friction_coefficient
        mu = b.friction_coefficient if mu is None else mu
        if mu is None:
            out.append(jnp.asarray(jnp.nan))
            continue
        if b.groove_angle_deg is not None and name not in scene.route.back_side:
            mu = mu / jnp.sin(jnp.deg2rad(b.groove_angle_deg) / 2)
        out.append(jnp.asarray(mu))
    return jnp.stack(out)


def given(scene: Scene) -> list[int]:
    """Route indices of the entries with a friction coefficient (the scene's structure)."""
    b = scene.belt
    return [i for i, name in enumerate(scene.route.order)
            if b.friction_coefficient is not None or (name != TENSIONER and scene.pulley(name).friction_coefficient is not None)]


def demand(forces, wrap):
    """Friction coefficient each arc needs (-), route order: |ln(F_out / F_in)| / wrap.

    forces: each span's force on the pulleys (N, route order along the last axis: span i leaves entry i); wrap:
    wrap angles (rad).  NaN where a span's force is not positive (a slack or supercritical span
    carries nothing: no capstan ratio)."""
    forces = jnp.asarray(forces)
    f_in = jnp.roll(forces, 1, axis=-1)  # span i-1 arrives at entry i
    ok = (forces > 0) & (f_in > 0)
    ratio = jnp.where(ok, forces / jnp.where(ok, f_in, 1.0), 1.0)
    return jnp.where(ok, jnp.abs(jnp.log(ratio)) / wrap, jnp.nan)


def margins(needed, available):
    """Slip margin 1 - mu_needed / mu' (-) per arc; NaN where mu' is not given."""
    return 1.0 - needed / available


def assess(scene: Scene, forces, wrap) -> dict:
    """Per route entry: wrap (deg), friction needed, available (None if not given) and slip margin
    (None if not given), for a steady state whose spans pull the pulleys with ``forces`` (N)."""
    need = np.asarray(demand(forces, np.asarray(wrap)))
    have = np.asarray(effective_coefficients(scene))
    margin = np.asarray(margins(need, have))
    out = {}
    for i, name in enumerate(scene.route.order):
        out[name] = dict(
            wrap_deg=float(np.degrees(wrap[i])),
            friction_needed=float(need[i]),
            friction_available=None if np.isnan(have[i]) else float(have[i]),
            slip_margin=None if np.isnan(have[i]) else float(margin[i]),
        )
    return out


def slipping(assessment: dict) -> list[str]:
    """The route entries whose arcs would slip (slip margin below 0)."""
    return [k for k, v in assessment.items() if v["slip_margin"] is not None and v["slip_margin"] < 0]


def slip_warning(assessment: dict, state: str) -> str:
    """One line on the arcs that would slip at ``state`` ("operating point" ...), or ""."""
    bad = slipping(assessment)
    if not bad:
        return ""
    parts = [f"{k} needs mu' = {assessment[k]['friction_needed']:.3g}, has {assessment[k]['friction_available']:.3g}"
             for k in bad]
    return (f"the belt would slip at the {state} ({'; '.join(parts)}): the capstan limit is exceeded, and this "
            "model's belt does not slip")
