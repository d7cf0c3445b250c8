"""Gradient-based layout optimisation of a drive: move parameters so that objectives fall and
constraints hold, with gradients through the statics and the (gyroscopic) modal analysis.

Optimisation file (TOML)
------------------------
Top level (all optional): ``steps`` (int >= 1, default 150: most optimiser steps),
``learning_rate`` (> 0, default 0.01: Adam's step in scaled variables, decayed along a cosine
to a tenth of it over ``steps``), ``tolerance`` (>= 0, default 1e-4) and ``patience`` (int >= 1,
default 30): stop when the best loss has not fallen by more than ``tolerance`` (relative) for
``patience`` steps, or when it reaches 0;
``elements_per_span`` (int, 1 to 400): a coarser mesh for the optimisation (the result is checked
with the scene's own mesh at the end); ``description`` (string).  Then tables::

    [[variable]]                         # one per parameter to move; every other parameter is fixed
    parameter = "tensioner.pivot.x"      # a beltjax.parameters path (file units)
    lower = 0.60                         # bounds, lower < upper; the scene's value must lie inside
    upper = 0.70
    # scale = 0.01                       # optional: typical change (file units), default upper - lower

    [[objective]]
    kind = "resonance_band"              # keep modes out of excitation-order lines over a speed band
    orders = [2.0]                       # multiples of the drive pulley's speed
    rpm = [1700, 2300]                   # the drive pulley's speed band (rpm), lower < upper
    modes = "span"                       # "span" (the modes labelled transverse at the band's lowest
                                         # speed, at the start), "all" (every flexible mode) or N
                                         # (the N lowest flexible modes)
    margin_hz = 2.0                      # wanted distance from the order line (Hz, default 2)
    speeds = 9                           # speeds sampled in the band (2-64, default 9)
    weight = 1.0                         # default 1; the term is weight * sum(need_hz^2)

    [[objective]]
    kind = "hub_load"                    # magnitude of the belt's force on one hub (N)
    pulley = "alternator"                # a route entry ("tensioner" for the idler)
    weight = 0.001                       # the term is weight * |F| / (1 N)

    [[constraint]]                       # all optional; each adds weight * sum((violation/unit)^2)
    kind = "min_wrap_deg"                # wrap angle >= value on one pulley (key pulley) or on all
    value = 150
    [[constraint]]
    kind = "static_tension"              # min <= span tension <= max (N), every span or key span
    min = 300
    max = 700
    [[constraint]]
    kind = "arm_angle_deg"               # tensioner arm angle window (deg), min and/or max
    min = 30
    max = 60
    [[constraint]]
    kind = "no_overlap"                  # every two pulleys keep a clearance (m) between rims
    clearance = 0.005

Every constraint also takes ``weight`` (default 100) and ``tolerance`` (the violation still
reported as satisfied; defaults 0.5 deg, 2 N, 0.2 deg, 0.2 mm).  Penalty units: 1 deg, 10 N,
1 deg, 1 mm.  Static quantities (tensions, hub forces, wraps, arm angle, gaps) are those of the
static state at the scene's own drive speed (what ``beltjax statics`` reports).

The resonance measure
---------------------
For one order k and one mode m, g(s) = f_m(s) - k s / 60 at the sampled speeds s of the band.
The mode is clear of the order line over the band, with margin mu, when it lies below the line
at every sampled speed (g <= -mu) or above it at every one (g >= mu).  The shift it still needs
is ``need = min(max_s(g + mu), max_s(mu - g))^+``: the smaller of the moves down and up that
would clear it (the max over speeds is a log-sum-exp with a 0.5 Hz temperature, which errs on
the safe side).  ``need`` is 0 for a mode that never comes near the line, so "all" is a sum of
one function over every eigenvalue: repeated eigenvalues (equal spans) enter symmetrically and
the gradient stays exact (DESIGN.md, "Measured facts").  Frequencies are sorted per speed (no
mode tracking); "span" fixes the positions of the transverse modes among the sorted ones at
the start of the optimisation (the final report labels them again).

Not provided: a "tension_fluctuation" or "arm_motion" objective.  Both are responses to the
crank's speed fluctuation and the accessories' torque pulsation, so they need the damped forced
response (transients or a harmonic-balance solve) and the dynamic load data of the engine; a
quasi-static or modal surrogate would rank layouts without that data, so neither is offered.

Method
------
Adam (optax) on the scaled variables x / scale, projected onto the bounds after each step
(clip); gradients by ``jax.grad`` through :func:`beltjax.statics.install` and
:func:`~beltjax.statics.equilibrium` (implicit function theorem) and the gyroscopic modal
problem at every sampled speed.  The speeds go through ``lax.map``: measured as fast as
``vmap`` on the 2-core CPU (0.45 against 0.48 s per value and gradient of the 8-element bench
at 9 speeds), each speed keeps its own Newton loop, and with ``vmap`` the gradient of the
batched loop hung XLA's CPU runtime before beltjax pinned its CPU thread pool at import.  The
mode selection ("span") is an argument of the compiled function (0/1 weights per sorted mode),
so labelling the modes does not recompile, and the same compiled function gives the
before/after Campbell diagrams (its speeds are an argument too).  A step to a layout that
cannot be built (the belt cannot be fitted, no equilibrium, unstable, a non-finite loss or
gradient) is rejected and the learning rate halved; the result is the best feasible layout
met, never NaN.

API: :func:`parse` / :func:`load` (a spec -> :class:`Problem`), :func:`measures`,
:func:`mode_masks`, :func:`loss_terms` and :func:`loss` (pure JAX), :func:`optimise` (->
:class:`OptimizeResult`), :func:`check` (a layout on the scene's own mesh: statics, Campbell
diagram, constraint and resonance reports) and :func:`run` (the ``beltjax optimize`` command:
optimize.json, optimized_scene.toml, before/after layouts and Campbell diagrams, history).
"""

__all__ = [
    "CONSTRAINTS", "OBJECTIVES", "SOFT_HZ", "Constraint", "Objective", "OptimizeError", "OptimizeResult", "Problem",
    "Variable", "band_need", "band_rpm", "check", "constraint_report", "edit_scene_text", "evaluator", "load", "loss",
    "loss_terms", "measures", "mode_labels", "mode_masks", "optimise", "parse", "plot_history", "relevant_modes",
    "resonance_report", "run", "sample_rpm", "term_names", "terms_from_measures", "working_scene",
]

from beltjax.optimize.problem import (  # noqa: F401
    CONSTRAINTS, OBJECTIVES, SOFT_HZ, Constraint, Objective, OptimizeError, Problem, Variable, _band_starts, _bands,
    _parse_constraint, _parse_objective, _parse_variable, band_rpm, load, parse, sample_rpm, working_scene,
)
from beltjax.optimize.loss import (  # noqa: F401
    _compiled, _labels_and_masks, _loss_key, _measures_jit, band_need, loss, loss_terms, measures, mode_labels,
    mode_masks, term_names, terms_from_measures,
)
from beltjax.optimize.solver import OptimizeResult, optimise  # noqa: F401
from beltjax.optimize.report import (  # noqa: F401
    _describe_constraint, _value_text, check, constraint_report, evaluator, relevant_modes, resonance_report,
)
from beltjax.optimize.scenefile import _verify_scene_text, edit_scene_text  # noqa: F401
from beltjax.optimize.plots import plot_history  # noqa: F401
from beltjax.optimize.command import run  # noqa: F401
