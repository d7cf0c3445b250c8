"""Gradient-based layout optimisation of a drive: move parameters so that objectives fall and
constraints hold, with gradients through the statics and the (gyroscopic) modal analysis.

Optimisation file (TOML)
------------------------
Top level (all optional): ``steps`` (int >= 1, default 150: most optimiser steps of one
start), ``learning_rate`` (> 0, default 0.01: Adam's step in scaled variables, decayed along a
cosine to a tenth of it over ``steps``), ``tolerance`` (>= 0, default 1e-4), ``patience``
(int >= 1, default 30) and ``min_steps`` (int >= 0, default 40): a start stops when its
smoothed loss has made no new low (by more than ``tolerance``, relative) against its previous
10 values for ``patience`` steps (or no new record for 3 x ``patience``), never before
``min_steps`` steps (:mod:`beltjax.optimize.stop`), or when the loss reaches 0; ``starts`` (int 1 to 16,
default 3): while no step has met the goal, the run tries further starts
(:mod:`beltjax.optimize.solver`); ``elements_per_span`` (int, 1 to 400): a coarser mesh for
the optimisation (the result is checked with the scene's own mesh at the end);
``description`` (string).  Then tables::

    [[variable]]                         # one per parameter to move; every other parameter is fixed
    parameter = "tensioner.pivot.x"      # a beltjax.parameters path (file units)
    lower = 0.60                         # bounds, lower < upper; the scene's value must lie inside
    upper = 0.70
    # scale = 0.01                       # optional: typical change (file units), default upper - lower

    [[objective]]
    kind = "resonance_band"              # keep modes out of excitation-order lines over a speed band
    orders = [2.0]                       # multiples of the drive pulley's speed
    rpm = [1700, 2300]                   # the drive pulley's speed band (rpm), lower < upper
    modes = "span"                       # "span" (the transverse span modes, chosen at every
                                         # sampled speed and step by their shapes), "all" (every
                                         # flexible mode) or N (the N lowest flexible modes)
    margin_hz = 2.0                      # wanted distance from the order line (Hz, default 2)
    tolerance_hz = 0.05                  # shift still needed that counts as clear (Hz, default 0.05)
    speeds = 9                           # speeds sampled in the band (2-64, default 9)
    weight = 1.0                         # default 1; the term is weight * sum(need_hz^2)

    [[objective]]
    kind = "hub_load"                    # magnitude of the belt's force on one hub (N)
    pulley = "alternator"                # a route entry ("tensioner" for the idler)
    weight = 0.001                       # the term is weight * |F| / (1 N)

    [[objective]]
    kind = "arm_motion"                  # the tensioner arm's largest peak-to-peak (deg) in the
    rpm = [700, 1000]                    #   periodic steady state over a crank speed band (beltjax
    speeds = 5                           #   orders: needs a driven crank, orders, lasting loads);
    settle_s = 1.0                       #   speeds sampled (default 5), transient before the cycle (s)
    weight = 1.0                         # the term is weight * max p2p / (1 deg)

    [[constraint]]                       # all optional; each adds weight * sum((violation/unit)^2)
    kind = "min_wrap_deg"                # wrap angle >= value on one pulley (key pulley) or on all
    value = 150
    [[constraint]]
    kind = "min_slip_margin"             # slip margin 1 - mu_needed / mu' at the operating point >= value
    value = 0.2                          # (capstan law; one pulley with key pulley, else every arc)
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

Accepted ranges (a number outside is refused when the file is read, naming its key, the range
and its reason; :data:`beltjax.optimize.problem.RANGES`): ``rpm`` that of the scene's drive
speeds (``drive.rpm`` of :mod:`beltjax.schema`, [0, 1e6] rpm), each of ``orders`` that of a
scene's fluctuation orders (``fluctuation.order``, (0, 1000])), ``margin_hz`` and
``tolerance_hz`` [0, 1e6] Hz, ``weight`` [0, 1e6], ``steps`` and ``patience`` 1 to 1e5,
``min_steps`` 0 to 1e5, ``learning_rate`` [1e-6, 10], ``tolerance`` [0, 1], ``scale`` 1e-6 to
1e3 x (upper - lower), ``settle_s`` that of ``beltjax orders --settle-s``, ``clearance`` [0, 100] m,
a tension window that of ``span.tension`` ([0, 1e8] N), an arm-angle window that of
``tensioner.arm_angle_deg``, a constraint's ``tolerance`` one in its own units (at most 360 deg
of wrap, 1e8 N, 3600 deg of arm angle, 100 m, a slip margin of 2).

The resonance measure
---------------------
For one order k and one mode m, g(s) = f_m(s) - k s / 60 at the sampled speeds s of the band.
The mode is clear of the order line over the band, with margin mu, when it lies below the line
at every sampled speed (g <= -mu) or above it at every one (g >= mu).  The shift it still needs
is ``need = min(max_s(g + mu), max_s(mu - g))^+``: the smaller of the moves down and up that
would clear it (the max over speeds is a log-sum-exp with a 0.5 Hz temperature, which errs on
the safe side).  ``need`` is 0 for a mode that never comes near the line, so "all" is a sum of
one function over every eigenvalue: repeated eigenvalues (equal spans) enter symmetrically and
the gradient stays exact (DESIGN.md, "Measured facts").  Frequencies are sorted per speed.
With "span" each sorted mode counts only at the speeds where it is a transverse span mode: its
weight there (1 for a span mode, falling to 0 for a mode whose transverse share trails by 0.1;
from its kinetic-energy shares, computed inside the compiled loss from its eigenvectors and held
out of the gradient: :mod:`beltjax.optimize.modes`) weights that speed in the log-sum-exp
(:func:`band_need`).  So when a span mode passes a rotational one inside the band (their
sorted places swap), the term follows the span mode across the swap, at every step.  Modes of two equal spans (a repeated pair) are both span modes with weight 1,
so the pair enters symmetrically and the gradient stays exact.  The report and the goal use
the exact max over the speeds where a mode's weight is 1 (where its label says "transverse");
every such mode counts fully in the loss too, so a zero resonance term means a clear band.

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
same compiled function gives the before/after Campbell diagrams (its speeds are an argument).
A step to a layout that cannot be built or run (the belt cannot be fitted, no equilibrium,
unstable, a span force on the pulleys at or below zero: past the critical speed,
:func:`beltjax.critical.span_forces`, a non-finite loss or gradient) is rejected and the
learning rate halved.

Stopping, starts and the result (:mod:`~beltjax.optimize.stop`, :mod:`~beltjax.optimize.solver`,
:mod:`~beltjax.optimize.goal`): a start ends when its smoothed loss has stalled (an early dip
cannot end it), after ``steps`` steps, or at a zero loss; the run then stops if some step met
the goal (built and run, no overlapping pulleys, every constraint within its tolerance, every
band clear), else tries the next start (deterministic Halton points of the bounds).  The result
is the best step that meets the goal, else the best feasible one; an overlapping layout or one
that cannot be built is never the result.  ``beltjax optimize`` checks it on the scene's own
mesh and exits with status 3 (GOAL_NOT_MET) when the goal is not met there, saying what is
missing and by how much (the summary, and ``goal_met`` / ``unmet`` in optimize.json).

API: :func:`parse` / :func:`load` (a spec -> :class:`Problem`), :func:`measures`,
:func:`mode_masks`, :func:`loss_terms` and :func:`loss` (pure JAX), :func:`optimise` (->
:class:`OptimizeResult`), :func:`check` (a layout on the scene's own mesh: statics, Campbell
diagram, constraint and resonance reports), :func:`unmet` (what a checked layout misses of the
goal) and :func:`run` (the ``beltjax optimize`` command: optimize.json, optimized_scene.toml,
before/after layouts and Campbell diagrams, history).

Modules: problem (the file), modes (frequencies and span weights in JAX), loss (the pure loss),
stop (the stop rule), goal (a layout's verdict, the result's rank), solver (the optimiser),
report (reports, the check), scenefile (the optimised scene file), plots, command.
"""

__all__ = [
    "CONSTRAINTS", "GOAL_NOT_MET", "OBJECTIVES", "SOFT_HZ", "Constraint", "Objective", "OptimizeError",
    "OptimizeResult", "Problem", "StopRule", "Variable", "band_need", "band_rpm", "band_weights", "check",
    "constraint_report", "edit_scene_text", "evaluator", "halton", "layout_status", "load", "loss", "loss_terms",
    "measures", "mode_labels", "mode_masks", "optimise", "parse", "plot_history", "problem_masks", "rank",
    "relevant_modes", "resonance_report", "run", "sample_rpm", "stall_step", "term_names", "terms_from_measures",
    "unmet", "working_scene",
]

from beltjax.optimize.problem import (  # noqa: F401
    CONSTRAINTS, OBJECTIVES, SOFT_HZ, Constraint, Objective, OptimizeError, Problem, Variable, _band_starts, _bands,
    _parse_constraint, _parse_objective, _parse_variable, band_rpm, load, parse, sample_rpm, working_scene,
)
from beltjax.optimize.loss import (  # noqa: F401
    _compiled, _loss_key, _measures_jit, band_need, band_weights, loss, loss_terms, measures, mode_masks,
    problem_masks, term_names, terms_from_measures,
)
from beltjax.optimize.stop import StopRule, stall_step  # noqa: F401
from beltjax.optimize.goal import layout_status, rank  # noqa: F401
from beltjax.optimize.solver import OptimizeResult, halton, optimise  # noqa: F401
from beltjax.optimize.report import (  # noqa: F401
    _describe_constraint, _value_text, check, constraint_report, evaluator, mode_labels, relevant_modes,
    resonance_report, unmet,
)
from beltjax.optimize.scenefile import _verify_scene_text, edit_scene_text, optimised_scene_text  # noqa: F401
from beltjax.optimize.plots import plot_history  # noqa: F401
from beltjax.optimize.command import GOAL_NOT_MET, run  # noqa: F401
