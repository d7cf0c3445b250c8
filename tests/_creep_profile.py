"""The belt a running drive's state holds, written out by classical creep theory: the reference
of the running belt's compatibility (tests/test_operating_point.py,
benchmarks/running_belt_length.py), apart from the model's own first-order formula
(:func:`beltjax.friction.arc_belt_moved`); and the scene texts of one drive whose belt grips or
creeps."""

from __future__ import annotations

import math
import re

import numpy as np

from beltjax import friction, span


def belt_held(sc, r, arcs_as_installed: bool = False) -> float:
    """Unstretched belt (m) that the running drive's state r holds, by quadrature: each span's
    tangent length over its stretch, and on each arc the belt that ran on there by classical creep
    theory, at the arriving span's tension where it adheres and, over the sliding arc at the exit
    (ln(F_out / F_in) / mu'), at the capstan law's exponential force F_in (F_out / F_in)^s plus the
    centrifugal part; every stretch from the tension by the axial law.  arcs_as_installed: the
    arcs at the installation stretch instead (the compatibility of a belt that never ran)."""
    stretch = lambda T: np.asarray(span.stretch_for_tension(np.asarray(T, dtype=float), float(sc.belt.EA)))  # noqa: E731
    T, F = np.asarray(r.span_tensions_N), np.asarray(r.span_forces_N)
    g = sc.geometry(math.radians(r.tensioner_angle_deg) if sc.tensioner is not None else 0.0, check=False)
    lengths, wraps, radii = np.asarray(g.span_length), np.asarray(g.wrap), np.asarray(r.inst.radii)
    mu = np.asarray(friction.effective_coefficients(sc, np))
    held = float(np.sum(lengths / stretch(T)))
    s = np.linspace(0.0, 1.0, 20001)
    for i in range(len(T)):
        if arcs_as_installed:
            held += radii[i] * wraps[i] / float(r.inst.stretch)
            continue
        x = math.log(F[i] / F[i - 1])
        slide = min(abs(x) / mu[i], wraps[i]) if np.isfinite(mu[i]) else 0.0
        Ts = F[i - 1] * np.exp(x * s) + (T[i - 1] - F[i - 1]) + ((T[i] - F[i]) - (T[i - 1] - F[i - 1])) * s
        held += radii[i] * ((wraps[i] - slide) / stretch(T[i - 1]) + slide * np.trapezoid(1 / stretch(Ts), s))
    return held


def gripping(txt: str) -> str:
    """A scene text without ``belt_slip`` in its effects (a belt that grips every rim)."""
    return re.sub(r'"belt_slip",? ?', "", txt).replace(", ]", "]")


def creeping(txt: str) -> str:
    """A scene text with ``belt_slip`` listed first among its effects (a belt that creeps)."""
    return re.sub(r"effects = \[", 'effects = ["belt_slip", ', gripping(txt), count=1).replace('"belt_slip", ]',
                                                                                              '"belt_slip"]')
