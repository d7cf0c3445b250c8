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
the arc would slip.  The whole arc is then sliding (creep at the limit).  Classical creep
theory gives each arc's sliding arc, the speed a driven pulley loses to creep, and the belt a
running belt's arcs hold (:func:`arc_belt_moved`, the compatibility the operating point solves);
a sliding belt's dynamics is :mod:`beltjax.drive.belt_slip`'s.  Units: SI, angles rad.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from beltjax.scene import TENSIONER, Scene


def effective_coefficients(scene: Scene, xp=jnp):
    """Effective friction coefficient mu' (-) per route entry, NaN where the scene gives none
    (pure: differentiable in the coefficients and the groove angle; xp as :func:`demand`)."""
    b = scene.belt
    out = []
    for name in scene.route.order:
        mu = None if name == TENSIONER else scene.pulley(name).friction_coefficient
        mu = b.friction_coefficient if mu is None else mu
        if mu is None:
            out.append(xp.asarray(xp.nan))
            continue
        mu = xp.asarray(mu)
        if b.groove_angle_deg is not None and name not in scene.route.back_side:
            mu = mu / xp.sin(xp.deg2rad(xp.asarray(b.groove_angle_deg)) / 2)
        out.append(mu)
    return xp.stack(out)


def given(scene: Scene) -> list[int]:
    """Route indices of the entries with a friction coefficient (the scene's structure)."""
    b = scene.belt
    return [i for i, name in enumerate(scene.route.order)
            if b.friction_coefficient is not None or (name != TENSIONER and scene.pulley(name).friction_coefficient is not None)]


def demand(forces, wrap, xp=jnp):
    """Friction coefficient each arc needs (-), route order: |ln(F_out / F_in)| / wrap.

    forces: each span's force on the pulleys (N, route order along the last axis: span i leaves entry i); wrap:
    wrap angles (rad).  NaN where a span's force is not positive (a slack or supercritical span
    carries nothing: no capstan ratio).  xp: the array module (numpy for host arrays: no
    dispatch of small device computations)."""
    forces = xp.asarray(forces)
    f_in = xp.roll(forces, 1, axis=-1)  # span i-1 arrives at entry i
    ok = (forces > 0) & (f_in > 0)
    ratio = xp.where(ok, forces / xp.where(ok, f_in, 1.0), 1.0)
    return xp.where(ok, xp.abs(xp.log(ratio)) / wrap, xp.nan)


def margins(needed, available):
    """Slip margin 1 - mu_needed / mu' (-) per arc; NaN where mu' is not given."""
    return 1.0 - needed / available


def arc_margins(scene: Scene, forces, wrap, xp=jnp):
    """(friction each arc needs (-), per route entry; slip margins (-) of the entries with a
    coefficient, in :func:`given` order) for spans that pull the pulleys with ``forces`` (N, route
    order along the last axis), wraps ``wrap`` (rad).  A span that carries nothing (slack, or
    past the critical speed: flagged on its own) counts as 1e-9 N.  The one assessment of
    transients, sweeps and optimisation; xp as :func:`demand`."""
    need = demand(xp.maximum(forces, 1e-9), wrap, xp)
    idx = np.asarray(given(scene), dtype=int)
    return need, margins(need[..., idx], effective_coefficients(scene, xp)[idx])


def sliding_arcs(needed, wrap, available, xp=jnp):
    """Sliding arc of each wrap (rad) by classical creep theory (Grashof, Reynolds): the belt
    slides over the part of the arc where its tension changes, ln(F_out / F_in) / mu' =
    wrap mu_needed / mu' (the rest, from the entry, adheres); the whole wrap at or past the
    capstan limit.  NaN where mu' is not given."""
    return xp.minimum(needed * wrap / available, wrap)


def creep_speed_loss(stretches, drive_index: int, xp=jnp):
    """Speed lost to creep (-) per route entry, relative to the drive pulley, by classical creep
    theory: a pulley turns with the belt where it adheres, at the entry of its wrap, so its rim
    runs at the arriving span's speed, c lam_in (c: the belt's unstretched flow, lam_in: that
    span's stretch); 1 - lam_in / lam_in(drive pulley), e.g. 1 - (1 + eps_slack) / (1 + eps_tight)
    for the driven pulley of a two-pulley drive.  stretches: each span's stretch (-), route order
    (span i leaves entry i) along the last axis."""
    lam_in = xp.roll(xp.asarray(stretches), 1, axis=-1)
    return 1.0 - lam_in / lam_in[..., drive_index : drive_index + 1]


def arc_belt_moved(forces, stretches, wrap, radii, stretch0, available, xp=jnp):
    """Belt (m) each wrapped arc of a running belt has handed its exit span since installation,
    by classical creep theory: the compatibility of a running belt (Rubin 2000, "An exact
    solution for steady motion of an extensible belt in multipulley belt drive systems").

    As installed, every arc holds the belt at the installation stretch lam_0.  Once the belt
    runs, the belt on an arc is the belt that ran on at its entry: it adheres there at the
    arriving span's stretch lam_in, and over the sliding arc at the exit (ln(F_out / F_in) /
    mu', :func:`sliding_arcs`) its force goes exponentially from F_in to F_out (the capstan
    law) and its stretch with it, to the exit span's lam_out.  An arc of radius R and wrap
    theta then holds R [theta (lam_in - lam_0) + phi_s g (lam_out - lam_in)] less belt (to first
    order in the strains) than as installed, g = 1 / ln r - 1 / (r - 1) the sliding arc's mean
    share of the step (r = F_out / F_in; g -> 1/2 as r -> 1), and hands it to its exit span.
    A drive whose spans' tensions differ (a loaded one) so holds its tensions at a level other
    than the one that keeps the arcs as installed: both spans' tensions of a two-pulley drive
    rise, since the tight arc's sliding zone holds less of the slack belt than the slack one's.

    forces: each span's force on the pulleys (N, T - rhoA c^2 lam, route order: span i leaves
    entry i); stretches: the spans' l / L0 (-); wrap (rad) and radii (m) per entry; stretch0:
    lam_0 (-); available: mu' per entry (NaN where none is given: no sliding arc, the limit of
    a grip without bound).  An arc past the capstan limit slides over its whole wrap.  Smooth
    where the arcs hold (C1 where F_in = F_out); xp as :func:`demand`."""
    forces, stretches = xp.asarray(forces), xp.asarray(stretches)
    f_in, lam_in = xp.roll(forces, 1, axis=-1), xp.roll(stretches, 1, axis=-1)
    ok = (forces > 0) & (f_in > 0)
    x = xp.where(ok, xp.log(xp.where(ok, forces, 1.0) / xp.where(ok, f_in, 1.0)), 0.0)  # ln(F_out / F_in)
    mu = xp.where(xp.isnan(available), xp.inf, available)
    slide = xp.minimum(xp.abs(x) / mu, wrap)
    small = xp.abs(x) < 1e-4
    xs = xp.where(small, 1.0, x)
    share = xp.where(small, 0.5 - x / 12.0, 1.0 / xs - 1.0 / xp.expm1(xs))
    return radii * (wrap * (lam_in - stretch0) + slide * share * (stretches - lam_in))


def assess(scene: Scene, forces, wrap, stretches=None, drive_index: int = 0) -> dict:
    """Per route entry, for a steady state whose spans pull the pulleys with ``forces`` (N):
    wrap (deg), friction needed, available (None if not given), slip margin and sliding arc
    (deg; None if no coefficient is given), and, with the spans' ``stretches`` (-), the creep
    speed loss relative to the drive pulley (route index ``drive_index``)."""
    wrap = np.asarray(wrap)
    need = demand(np.asarray(forces), wrap, np)
    have = effective_coefficients(scene, np)
    margin = margins(need, have)
    arcs = np.degrees(sliding_arcs(need, wrap, have, np))
    loss = None if stretches is None else creep_speed_loss(np.asarray(stretches), drive_index, np)
    out = {}
    for i, name in enumerate(scene.route.order):
        given = not np.isnan(have[i])
        out[name] = dict(
            wrap_deg=float(np.degrees(wrap[i])),
            friction_needed=float(need[i]),
            friction_available=float(have[i]) if given else None,
            slip_margin=float(margin[i]) if given else None,
            sliding_arc_deg=float(arcs[i]) if given else None,
            creep_speed_loss=None if loss is None else float(loss[i]),
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
