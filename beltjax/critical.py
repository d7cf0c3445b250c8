"""The critical belt speed: where a moving span stops pulling on its pulleys.

A span of elastic tension ``T`` (N) and stretch ``lam`` (its chord over its unstretched
length) that the belt runs through at the transport speed ``c`` (m of unstretched belt per
s; ``c = v / lam_0`` for the belt speed ``v`` at the drive pulley's rim and the
installation stretch ``lam_0``) pulls on the pulleys at its ends with

    F = T - rhoA c^2 lam     (N; rhoA the mass per unstretched metre)

the momentum flux of the moving belt (``rhoA c^2 lam = (rhoA / lam) (c lam)^2``: mass per
stretched metre times the span's belt speed squared) taking that much off the elastic
tension.  This is the span force of :func:`beltjax.drive.hub_forces` and of the
``span_forces_N`` output of :mod:`beltjax.transient` (with the ``transport`` effect).

Where ``F <= 0`` the belt no longer presses on the pulleys: the real belt lifts off (it
cannot push), the steady motion of the model has hub forces pointing the wrong way, and for
the hybrid model's flexible spans the transverse stiffness ``F / l`` of the moving string
vanishes with it (bending alone keeps a little).  Neither fidelity is physical there.  The
belt speed at which the first span's ``F`` reaches zero is the drive's **critical speed**;
at given tensions span ``s``'s own is ``v_s = lam_0 sqrt(T_s / (rhoA lam_s))``
(``sqrt(T lam / rhoA)`` when ``lam_s = lam_0``, as :mod:`beltjax.span` reports).  In a drive
whose tensions do not depend on the speed (fixed centres: the elastic tension stays the
installation tension) that is the critical speed; a tensioner raises the tension with the
speed, so the drive's critical speed follows the equilibrium branch
(:func:`critical_speed`).

The check holds whatever effects the scene lists: without ``transport`` the model leaves
the belt's momentum flux out, but the real belt still has it, so a speed past the critical
speed is flagged there too (the model's answer would be that of a belt at rest).

Pure functions (``jax.numpy``; jit, vmap and grad): :func:`pulley_forces`,
:func:`span_critical_speeds`, :func:`span_state`, :func:`span_forces` and
:func:`supercritical` (the check for optimisers and batched sweeps: a smooth margin and a
flag).  :func:`message` words the one-line error.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from beltjax import drive
from beltjax.scene import Scene
from beltjax.drive.effects import effects_of

#: relative width to which :func:`critical_speed` brackets the critical belt speed
CRITICAL_RTOL = 1e-7


def pulley_forces(tensions, span_stretches, transport_speed, rhoA):
    """Force of each span on its pulleys, ``T - rhoA c^2 lam`` (N).

    tensions: elastic span tensions T (N), shape (n,) (any leading batch shape);
    span_stretches: each span's chord over its unstretched length lam (-); transport_speed:
    c (m/s of unstretched belt, scalar or broadcastable); rhoA: mass per unstretched length
    (kg/m).  Pure, differentiable.
    """
    return tensions - rhoA * transport_speed**2 * span_stretches


def span_critical_speeds(tensions, span_stretches, stretch, rhoA):
    """Belt speed (m/s, at the drive pulley's rim) at which each span's force on the pulleys
    would reach zero at these tensions: ``lam_0 sqrt(T / (rhoA lam))``; 0 for a slack span.

    tensions (N) and span_stretches (-) as :func:`pulley_forces`; stretch: the installation
    stretch lam_0 (belt speed v = c lam_0); rhoA (kg/m).  Pure.
    """
    return stretch * jnp.sqrt(jnp.maximum(tensions, 0.0) / (rhoA * span_stretches))


def span_state(scene: Scene, qi, inst):
    """(elastic tensions N, span stretches -) at the independent coordinates qi: the mean axial
    force of each span (:func:`beltjax.drive.span_tensions`) and its chord over its
    unstretched length.  Pure."""
    q = drive.full_coordinates(qi, scene, inst)
    lengths = drive.full_span_lengths(q, scene)
    return drive.span_tensions(q, scene, inst), span_stretches(scene, inst, lengths)


def span_stretches(scene: Scene, inst, lengths):
    """Chord over unstretched length of each span, from the chord lengths (m).  Pure."""
    return lengths / (drive.element_length(scene, inst) * drive.span_elements(scene))


def span_forces(scene: Scene, qi, inst, speed):
    """Force of each span on its pulleys (N), route order, at the state qi (a steady motion,
    e.g. from :func:`beltjax.statics.equilibrium`) and belt speed ``speed`` (m/s).

    The check to call in optimisers and batched sweeps: pure and differentiable in every
    scene parameter (through the statics' implicit derivatives); the drive is past its
    critical speed where any entry is <= 0, so ``min(span_forces) > 0`` (or a margin, e.g.
    ``min / T_installed > 0.1``) is the constraint that keeps a layout subcritical.
    """
    tensions, lam = span_state(scene, qi, inst)
    return pulley_forces(tensions, lam, drive.transport_speed(scene, inst, speed), scene.belt.rhoA)


def supercritical(scene: Scene, qi, inst, speed):
    """True (a JAX bool) where a moving drive (``speed`` m/s > 0) has a span whose force on the
    pulleys is <= 0 at the state qi: past its critical speed (:func:`span_forces`).  Pure."""
    return (jnp.abs(speed) > 0) & ~jnp.all(span_forces(scene, qi, inst, speed) > 0)


def output_forces(scene: Scene, out, speed) -> np.ndarray:
    """Each span's force on the pulleys (N) from static outputs ``out``
    (:func:`beltjax.statics.static_outputs`: tensions, lengths, inst) at belt speed ``speed`` (m/s)."""
    inst = out["inst"]
    lam = span_stretches(scene, inst, out["lengths"])
    return np.asarray(pulley_forces(out["tensions"], lam, speed / inst.stretch, scene.belt.rhoA))


def critical_speed(scene: Scene, speed: float) -> float | None:
    """The drive's critical belt speed (m/s) below ``speed`` (m/s), along its steady motions.

    The speed at which the first span's force on the pulleys reaches zero, bracketed to
    :data:`CRITICAL_RTOL` by bisection on the static equilibrium
    (:func:`beltjax.statics.solve_at`) at each trial speed, started at the speed where the
    spans' forces at ``speed`` would vanish at their tensions there (the answer itself when
    the tensions do not depend on the speed, as with fixed centres: two solves).  Returns
    None when the drive is not past it at ``speed``, or when what ends the subcritical range
    below ``speed`` is a speed without a converged equilibrium rather than a vanishing force.
    """
    from beltjax import statics  # statics imports this module

    scene = drive.canonical(scene)
    speed = abs(float(speed))

    def trial(u):  # +1: converged, every force > 0; -1: converged, a force <= 0; 0: not converged
        out, conv, _, _ = statics.solve_at(scene, u)
        if not conv:
            return 0, out
        return (1 if np.all(output_forces(scene, out, u) > 0) else -1), out

    top, out = trial(speed)
    if top == 1 or speed == 0.0:
        return None
    lo, hi, hi_kind = 0.0, speed, top
    if top == -1:
        inst = out["inst"]
        lam = span_stretches(scene, inst, out["lengths"])
        guess = float(np.min(span_critical_speeds(out["tensions"], lam, inst.stretch, scene.belt.rhoA)))
        if 0.0 < guess < speed:
            for u in (guess * (1 - CRITICAL_RTOL / 2), guess * (1 + CRITICAL_RTOL / 2)):
                k = trial(u)[0]
                if k == 1:
                    lo = max(lo, u)
                elif u < hi:
                    hi, hi_kind = u, k
    while hi - lo > CRITICAL_RTOL * hi:
        mid = 0.5 * (lo + hi)
        k = trial(mid)[0]
        if k == 1:
            lo = mid
        else:
            hi, hi_kind = mid, k
    return hi if hi_kind == -1 else None


def drive_rpm(scene: Scene, speed: float) -> float:
    """The drive pulley's speed (rpm) at belt speed ``speed`` (m/s)."""
    p = scene.pulley(scene.route.order[drive.drive_pulley(scene)])
    return float(speed) / float(p.radius) * 60.0 / (2.0 * math.pi)


def message(scene: Scene, speed: float, critical_speed: float | None, forces=None, tensions=None) -> str:
    """The one-line error for a drive past its critical speed.

    speed, critical_speed: belt speeds (m/s; critical_speed None when it could not be
    located); forces, tensions: each span's force on the pulleys and elastic tension (N) at
    ``speed`` (None when no steady state was found there).  Names the span with the lowest force.
    """
    drv = scene.route.order[drive.drive_pulley(scene)]
    head = f"belt speed {speed:.4g} m/s ({drive_rpm(scene, speed):.5g} rpm of {drv}) is past the critical speed"
    crit = ("" if critical_speed is None else
            f" {critical_speed:.4g} m/s ({drive_rpm(scene, critical_speed):.5g} rpm)")
    note = ("" if effects_of(scene).moving_belt else
            " (the scene leaves out the \"transport\" effect, so the model would not show it)")
    advice = "lower the speed below the critical speed or raise the belt tension"
    if forces is None:
        return (f"{head}{crit}, where a span's force on the pulleys (tension less rhoA c^2 lam) reaches zero; no "
                f"steady state was found at {speed:.4g} m/s{note}; {advice}")
    forces, tensions = np.asarray(forces, float), np.asarray(tensions, float)
    k = int(np.argmin(forces))
    name = drive.span_names(scene)[k]
    return (f"{name}: {head}{crit}: the span's force on the pulleys would be {forces[k]:.4g} N (tension "
            f"{tensions[k]:.4g} N less rhoA c^2 lam = {tensions[k] - forces[k]:.4g} N), so the belt would lift off "
            f"the pulleys and the steady state is not physical{note}; {advice}")
