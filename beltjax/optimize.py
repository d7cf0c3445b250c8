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

from __future__ import annotations

import dataclasses
import functools
import json
import math
import pathlib
import re
import sys
import time
import tomllib
from dataclasses import dataclass, field
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np
import optax

from beltjax import drive, drive_modal, parameters, statics, textfile, tomltable
from beltjax.errors import BeltjaxError
from beltjax.scene import MAX_ELEMENTS_PER_SPAN, TENSIONER, Scene, SceneError, loads_scene
from beltjax.tomltable import describe

#: temperature (Hz) of the log-sum-exp maximum over the sampled speeds
SOFT_HZ = 0.5
OBJECTIVES = ("resonance_band", "hub_load")
CONSTRAINTS = ("min_wrap_deg", "static_tension", "arm_angle_deg", "no_overlap")
#: penalty unit and default tolerance of each constraint kind (its own units)
_UNIT = {"min_wrap_deg": 1.0, "static_tension": 10.0, "arm_angle_deg": 1.0, "no_overlap": 1e-3}
_TOLERANCE = {"min_wrap_deg": 0.5, "static_tension": 2.0, "arm_angle_deg": 0.2, "no_overlap": 2e-4}
_UNIT_NAME = {"min_wrap_deg": "deg", "static_tension": "N", "arm_angle_deg": "deg", "no_overlap": "m"}
_TOP_KEYS = ("steps", "learning_rate", "tolerance", "patience", "elements_per_span", "description",
             "variable", "objective", "constraint")
_VARIABLE_KEYS = ("parameter", "lower", "upper", "scale")
_OBJECTIVE_KEYS = {
    "resonance_band": ("kind", "orders", "rpm", "modes", "margin_hz", "speeds", "weight"),
    "hub_load": ("kind", "pulley", "weight"),
}
_CONSTRAINT_KEYS = {
    "min_wrap_deg": ("kind", "value", "pulley", "weight", "tolerance"),
    "static_tension": ("kind", "min", "max", "span", "weight", "tolerance"),
    "arm_angle_deg": ("kind", "min", "max", "weight", "tolerance"),
    "no_overlap": ("kind", "clearance", "weight", "tolerance"),
}


class OptimizeError(BeltjaxError):
    """A bad optimisation file or an impossible start: one line naming the key (``key``)."""


# --------------------------------------------------------------------------- the problem


@dataclass(frozen=True)
class Variable:
    """A parameter to move: path (file units), bounds lower < upper, scale (typical change)."""

    path: str
    lower: float
    upper: float
    scale: float


@dataclass(frozen=True)
class Objective:
    """One objective term.  resonance_band: orders, rpm = (lo, hi) of the drive pulley (rpm),
    modes ("span", "all" or a number of lowest flexible modes), margin_hz (Hz), speeds
    (samples in the band); hub_load: pulley (a route entry).  weight >= 0."""

    kind: str
    weight: float = 1.0
    orders: tuple[float, ...] = ()
    rpm: tuple[float, float] = (0.0, 0.0)
    modes: str | int = "span"
    margin_hz: float = 2.0
    speeds: int = 9
    pulley: str = ""


@dataclass(frozen=True)
class Constraint:
    """One penalised constraint: kind, bounds lower/upper (its units; None: none), pulley or
    span it is restricted to (None: all), penalty weight and report tolerance."""

    kind: str
    lower: float | None
    upper: float | None
    weight: float
    tolerance: float
    where: str | None = None


@dataclass(frozen=True)
class Problem:
    """A parsed optimisation file (see the module docstring); hashable, so compiled
    functions are shared between problems that are equal."""

    variables: tuple[Variable, ...]
    objectives: tuple[Objective, ...]
    constraints: tuple[Constraint, ...] = ()
    steps: int = 150
    learning_rate: float = 0.01
    tolerance: float = 1e-4
    patience: int = 30
    elements_per_span: int | None = None
    description: str = ""

    @property
    def paths(self) -> list[str]:
        """Parameter paths of the variables, in order."""
        return [v.path for v in self.variables]

    @property
    def scales(self) -> np.ndarray:
        """Scale of each variable (file units)."""
        return np.array([v.scale for v in self.variables])


def _raise(path: str, msg: str):
    raise OptimizeError(msg, path)


#: the optimisation file's reader: OptimizeError, its own wording of a few messages
_READ = tomltable.Reader(_raise, tomltable.Style(unknown_where=False, finite=True, choose=True, top="file"))


def _parse_variable(d, i: int, scene: Scene) -> Variable:
    key = f"variable[{i}]"
    t = _READ.table(d, key, _VARIABLE_KEYS)
    path = t.string("parameter", required=True)
    try:
        parameters.check(scene, path)
    except parameters.ParameterError as exc:
        raise OptimizeError(str(exc), f"{key}.parameter") from None
    lo = t.number("lower", required=True)
    hi = t.number("upper", required=True)
    for k, x in (("lower", lo), ("upper", hi)):
        try:  # a bound outside the parameter's accepted range (beltjax.schema)
            parameters.check_value(path, x)
        except parameters.ParameterError as exc:
            t.fail(k, f"{path} {str(exc)[len(path) + 2:]}")
    if not lo < hi:
        t.fail("upper", f"must be > lower = {lo!r}, got {hi!r}")
    scale = t.number("scale", required=False, default=hi - lo, positive=True)
    x0 = float(parameters.get_value(scene, path))
    if not math.isfinite(x0):
        t.fail("parameter", f"{path} is not given in the scene (it is solved for); "
               "optimise the belt key the scene gives")
    if not lo <= x0 <= hi:
        t.fail("parameter", f"the scene's value {x0:.6g} of {path} lies outside [lower, upper] = [{lo:g}, {hi:g}]")
    return Variable(path, lo, hi, scale)


def _route_entry(t: tomltable.Table, k: str, scene: Scene, required: bool) -> str | None:
    name = t.string(k, required=required)
    if name is not None and name not in scene.route.order:
        t.fail(k, f"unknown pulley {name!r}; route entries: {', '.join(scene.route.order)}")
    return name


def _kind(d, key: str, choices) -> str:
    """The ``kind`` of an objective or constraint table (checked before its other keys)."""
    if not isinstance(d, dict):
        raise OptimizeError(f"expected a table, got {describe(d)}", key)
    only = {k: d[k] for k in ("kind",) if k in d}
    return _READ.table(only, key, ("kind",)).string("kind", required=True, choices=choices)


def _parse_objective(d, i: int, scene: Scene) -> Objective:
    key = f"objective[{i}]"
    kind = _kind(d, key, OBJECTIVES)
    t = _READ.table(d, key, _OBJECTIVE_KEYS[kind])
    weight = t.number("weight", required=False, default=1.0, nonnegative=True)
    if kind == "hub_load":
        return Objective(kind, weight, pulley=_route_entry(t, "pulley", scene, True))
    orders = d.get("orders")
    if (not isinstance(orders, list) or not orders
            or any(isinstance(k, bool) or not isinstance(k, (int, float)) or not 0 < k < math.inf for k in orders)):
        got = (describe(orders) if not isinstance(orders, list) else repr(orders)) if orders is not None else "nothing"
        t.fail("orders", f"expected a non-empty array of positive finite numbers, got {got}")
    rpm = d.get("rpm")
    if (not isinstance(rpm, list) or len(rpm) != 2
            or any(isinstance(r, bool) or not isinstance(r, (int, float)) or not math.isfinite(r) for r in rpm)):
        got = describe(rpm) if rpm is not None else "nothing"
        t.fail("rpm", f"expected [lower, upper] speeds of the drive pulley (rpm), got {got}")
    if not 0 <= rpm[0] < rpm[1]:
        t.fail("rpm", f"need 0 <= lower < upper, got {rpm!r}")
    modes = d.get("modes", "span")
    if isinstance(modes, bool) or not (modes in ("span", "all") or (isinstance(modes, int) and modes >= 1)):
        t.fail("modes", f"expected \"span\", \"all\" or a number of lowest modes >= 1, got {describe(modes)}")
    return Objective(
        kind, weight, orders=tuple(float(k) for k in orders), rpm=(float(rpm[0]), float(rpm[1])), modes=modes,
        margin_hz=t.number("margin_hz", required=False, default=2.0, nonnegative=True),
        speeds=t.integer("speeds", required=False, default=9, minimum=2, maximum=64),
    )


def _parse_constraint(d, i: int, scene: Scene) -> Constraint:
    key = f"constraint[{i}]"
    kind = _kind(d, key, CONSTRAINTS)
    t = _READ.table(d, key, _CONSTRAINT_KEYS[kind])
    weight = t.number("weight", required=False, default=100.0, nonnegative=True)
    tol = t.number("tolerance", required=False, default=_TOLERANCE[kind], nonnegative=True)
    if kind == "min_wrap_deg":
        value = t.number("value", required=True)
        if not 0 < value < 360:
            t.fail("value", f"must lie in (0, 360) deg, got {value!r}")
        return Constraint(kind, value, None, weight, tol, _route_entry(t, "pulley", scene, False))
    if kind == "no_overlap":
        return Constraint(kind, t.number("clearance", required=False, default=0.0, nonnegative=True), None, weight, tol)
    if kind == "arm_angle_deg" and scene.tensioner is None:
        t.fail("kind", "the scene has no tensioner")
    lo, hi = t.number("min", required=False), t.number("max", required=False)
    if lo is None and hi is None:
        t.fail("min", "give min, max or both")
    if lo is not None and hi is not None and not lo < hi:
        t.fail("max", f"must be > min = {lo!r}, got {hi!r}")
    span = None
    if kind == "static_tension":
        span = t.string("span", required=False)
        if span is not None and span not in scene.route.span_names:
            t.fail("span", f"unknown span {span!r}; spans: {', '.join(scene.route.span_names)}")
    return Constraint(kind, lo, hi, weight, tol, span)


def parse(spec: dict, scene: Scene) -> Problem:
    """Validate an optimisation file given as a dict (parsed TOML) against ``scene``.

    Raises :class:`OptimizeError` (one line naming the key) for unknown keys or kinds, bad
    bounds, a parameter path the scene lacks, a start outside the bounds, no variables or
    no objectives, steps < 1 and the like.
    """
    t = _READ.table(spec, "", _TOP_KEYS)
    variables = tuple(_parse_variable(d, i, scene) for i, d in enumerate(t.tables("variable")))
    if not variables:
        raise OptimizeError("at least one [[variable]] is required", "variable")
    seen = [v.path for v in variables]
    for i, p in enumerate(seen):
        if p in seen[:i]:
            raise OptimizeError(f"{p} is listed twice", f"variable[{i}].parameter")
    objectives = tuple(_parse_objective(d, i, scene) for i, d in enumerate(t.tables("objective")))
    if not objectives:
        raise OptimizeError("at least one [[objective]] is required", "objective")
    constraints = tuple(_parse_constraint(d, i, scene) for i, d in enumerate(t.tables("constraint")))
    return Problem(
        variables=variables,
        objectives=objectives,
        constraints=constraints,
        steps=t.integer("steps", required=False, default=150, minimum=1),
        learning_rate=t.number("learning_rate", required=False, default=0.01, positive=True),
        tolerance=t.number("tolerance", required=False, default=1e-4, nonnegative=True),
        patience=t.integer("patience", required=False, default=30, minimum=1),
        elements_per_span=t.integer("elements_per_span", required=False, minimum=1, maximum=MAX_ELEMENTS_PER_SPAN),
        description=t.string("description", required=False, default=""),
    )


def load(path, scene: Scene) -> Problem:
    """Read and validate an optimisation file (TOML, read by :mod:`beltjax.textfile`: a regular
    file of bounded size); :class:`OptimizeError` names the file or key."""
    spec = textfile.load_toml(str(path), "optimisation", textfile.keyed(_raise))
    return parse(spec, scene)


def working_scene(scene: Scene, problem: Problem) -> Scene:
    """The scene the optimisation runs on: canonical, with ``problem.elements_per_span`` if set."""
    sc = drive.canonical(scene)
    if problem.elements_per_span is not None and problem.elements_per_span != sc.model.elements_per_span:
        sc = dataclasses.replace(sc, model=dataclasses.replace(sc.model, elements_per_span=problem.elements_per_span))
    return sc


def band_rpm(objective: Objective) -> np.ndarray:
    """Sampled speeds (rpm) of a resonance objective's band, ends included."""
    return np.linspace(objective.rpm[0], objective.rpm[1], objective.speeds)


def _bands(problem: Problem) -> list[Objective]:
    return [o for o in problem.objectives if o.kind == "resonance_band"]


def sample_rpm(problem: Problem) -> np.ndarray:
    """Every resonance objective's sampled speeds (rpm), concatenated in objective order."""
    parts = [band_rpm(o) for o in _bands(problem)]
    return np.concatenate(parts) if parts else np.zeros(0)


def _band_starts(problem: Problem) -> list[int]:
    """Index of each resonance objective's first sampled speed in :func:`sample_rpm`."""
    return [int(k) for k in np.cumsum([0] + [o.speeds for o in _bands(problem)])[:-1]]


def _pairs(n: int) -> list[tuple[int, int]]:
    return [(i, j) for i in range(n) for j in range(i + 1, n)]


# --------------------------------------------------------------------------- the pure loss


def measures(scene: Scene, problem: Problem, x, rpm=None) -> dict:
    """Every quantity the objectives and constraints use, at parameter values ``x`` (pure JAX).

    x: (n_variables,) values in file units; rpm: (S,) drive-pulley speeds (rpm, traceable;
    default :func:`sample_rpm`).  Static state at the scene's own speed: qi, q, inst, wrap_deg
    (n,), tensions_N (n,), span_lengths_m (n,), hub_N (n, 2), arm_deg (), gaps_m (pairs,)
    rim-to-rim distances of every two route entries; at each speed of ``rpm``: qi_speeds (S,
    n_i), freqs_hz (S, n_i) sorted, good (S,) (equilibrium converged and stable); feasible:
    belt fitted, every equilibrium converged and stable, spans taut, everything finite.
    """
    rpm = jnp.asarray(sample_rpm(problem) if rpm is None else rpm, dtype=jnp.float64)
    sc = parameters.set_values(scene, dict(zip(problem.paths, x)))
    inst = statics.install(sc)
    nr = drive_modal.n_rigid_modes(sc)
    gyro = sc.model.has("transport")

    def at(v):
        qv, _, iv = statics.equilibrium(sc, inst, speed=v)
        if rpm.shape[0] == 0:
            return qv, jnp.zeros(0), iv[0] > 0.5
        M, G, K = drive_modal.linearise(qv, sc, inst, v)
        stable, f = drive_modal.frequencies_from_matrices(M, G, K, nr, gyro, drive_modal.rigid_mode(sc, inst))
        return qv, f, stable & (iv[0] > 0.5)

    # the static state (the scene's own speed) and every sampled speed through one equilibrium
    # solver in the compiled function (a second copy of the Newton loop and its implicit
    # derivative cost ~20 % more compile time); lax.map: see the module docstring
    v0 = drive.belt_speed(sc)
    speeds = jnp.concatenate([jnp.reshape(v0, (1,)), drive.belt_speed(sc, rpm)])
    qs, freqs, good = jax.lax.map(at, speeds)
    if rpm.shape[0] == 0:
        freqs = jnp.zeros((1, drive.n_independent(sc)))
    qi = qs[0]
    q = drive.full_coordinates(qi, sc, inst)
    _, theta = drive.angles_and_arm(qi, sc, inst)
    tensions = drive.span_tensions(q, sc, inst)
    c, r = inst.centers, inst.radii
    m = dict(
        wrap_deg=jnp.degrees(inst.wrap), tensions_N=tensions, span_lengths_m=drive.full_span_lengths(q, sc),
        hub_N=drive.hub_forces(q, sc, inst, v0), arm_deg=jnp.degrees(theta),
        gaps_m=jnp.stack([jnp.linalg.norm(c[i] - c[j]) - r[i] - r[j] for i, j in _pairs(len(r))]),
        freqs_hz=freqs[1:], qi_speeds=qs[1:], good=good[1:], qi=qi, q=q,
    )
    lam = inst.stretch
    ok = (jnp.isfinite(inst.arm_angle) & (lam > 1.0) & (lam - 1.0 <= statics.MAX_INSTALL_STRAIN)
          & jnp.all((inst.wrap > 0) & (inst.wrap < 2 * jnp.pi)) & jnp.all(good) & jnp.all(tensions > 0))
    finite = jnp.all(jnp.stack([jnp.all(jnp.isfinite(a)) for a in m.values()]))
    m["inst"] = inst
    m["feasible"] = ok & finite
    return m


def mode_masks(problem: Problem, labels: list | None, n_modes: int, n_rigid: int) -> np.ndarray:
    """(n_resonance_objectives, n_modes) 0/1 weights of the sorted modes each resonance objective
    watches: "all" every flexible mode, N the N lowest flexible ones, "span" the modes labelled
    transverse (``labels[j]``: the labels at objective j's lowest speed)."""
    out = np.zeros((len(_bands(problem)), n_modes))
    for j, o in enumerate(_bands(problem)):
        if o.modes == "all":
            out[j, n_rigid:] = 1.0
        elif o.modes == "span":
            out[j] = [1.0 if "transverse" in lab else 0.0 for lab in labels[j]]
        else:
            out[j, n_rigid:n_rigid + int(o.modes)] = 1.0
    return out


def _soft_max(a, axis):
    return SOFT_HZ * jax.scipy.special.logsumexp(a / SOFT_HZ, axis=axis)


def band_need(freqs, rpm, orders, margin, soft: bool = True):
    """Shift (Hz) each mode still needs to clear each order line over a speed band.

    freqs (K, m) Hz at the sampled speeds rpm (K,); orders (o,).  Returns (o, m):
    min(max_s(g + margin), max_s(margin - g))^+ with g = f - k rpm / 60; the max over speeds
    is a log-sum-exp (temperature SOFT_HZ) when ``soft``, exact otherwise (numpy or JAX).
    """
    xp = jnp if soft else np
    line = xp.asarray(orders)[:, None] * xp.asarray(rpm)[None, :] / 60.0  # (o, K)
    g = xp.asarray(freqs)[None, :, :] - line[:, :, None]  # (o, K, m)
    if soft:
        down, up = _soft_max(g + margin, 1), _soft_max(margin - g, 1)
    else:
        down, up = np.max(g + margin, axis=1), np.max(margin - g, axis=1)
    return xp.maximum(xp.minimum(down, up), 0.0)


def _violations(c: Constraint, m: dict, scene: Scene, xp=jnp):
    """Per-element violations (constraint units, >= 0) and the reported value of a constraint."""
    if c.kind == "min_wrap_deg":
        w = m["wrap_deg"] if c.where is None else m["wrap_deg"][scene.route.order.index(c.where)][None]
        return xp.maximum(c.lower - w, 0.0), xp.min(w)
    if c.kind == "no_overlap":
        return xp.maximum(c.lower - m["gaps_m"], 0.0), xp.min(m["gaps_m"])
    if c.kind == "static_tension":
        v = m["tensions_N"] if c.where is None else m["tensions_N"][scene.route.span_names.index(c.where)][None]
    else:
        v = xp.reshape(m["arm_deg"], (1,))
    lo = xp.maximum(c.lower - v, 0.0) if c.lower is not None else xp.zeros_like(v)
    hi = xp.maximum(v - c.upper, 0.0) if c.upper is not None else xp.zeros_like(v)
    value = (xp.min(v), xp.max(v)) if c.kind == "static_tension" else v[0]
    return xp.concatenate([lo, hi]), value


def term_names(problem: Problem) -> list[str]:
    """Names of the loss terms: "objective[i] kind" then "constraint[j] kind"."""
    return ([f"objective[{i}] {o.kind}" for i, o in enumerate(problem.objectives)]
            + [f"constraint[{j}] {c.kind}" for j, c in enumerate(problem.constraints)])


def terms_from_measures(m: dict, scene: Scene, problem: Problem, masks, rpm=None, soft: bool = True) -> dict:
    """The loss terms (name -> scalar) from :func:`measures` (JAX, or numpy with soft=False).

    masks: :func:`mode_masks`; rpm: the speeds the frequencies were computed at (default
    :func:`sample_rpm`).  A resonance term is weight * sum(mask * need^2) (Hz^2), a hub load
    weight * |F| (N), a constraint weight * sum((violation / unit)^2).
    """
    xp = jnp if soft else np
    rpm = sample_rpm(problem) if rpm is None else rpm
    out, j = {}, 0
    names = term_names(problem)
    starts = _band_starts(problem)
    for i, o in enumerate(problem.objectives):
        if o.kind == "resonance_band":
            sl = slice(starts[j], starts[j] + o.speeds)
            need = band_need(m["freqs_hz"][sl], rpm[sl], np.asarray(o.orders), o.margin_hz, soft)
            out[names[i]] = o.weight * xp.sum(xp.asarray(masks)[j] * need**2)
            j += 1
        else:
            F = m["hub_N"][scene.route.order.index(o.pulley)]
            out[names[i]] = o.weight * xp.sqrt(xp.sum(F**2))
    for k, c in enumerate(problem.constraints):
        viol, _ = _violations(c, m, scene, xp)
        out[names[len(problem.objectives) + k]] = c.weight * xp.sum((viol / _UNIT[c.kind]) ** 2)
    return out


def loss_terms(scene: Scene, problem: Problem, x, masks):
    """(terms dict name -> scalar, feasible) at parameter values x (file units); pure JAX.

    masks: :func:`mode_masks` of the resonance objectives (needed with modes = "span": the
    labels come from :func:`mode_labels`).
    """
    m = measures(scene, problem, x)
    return terms_from_measures(m, scene, problem, masks), m["feasible"]


def loss(scene: Scene, problem: Problem, x, masks):
    """Total loss (objective terms + penalties) at x (file units); NaN where infeasible.

    Pure JAX: jit-, grad-able in x (and in every number of ``scene``).
    """
    terms, ok = loss_terms(scene, problem, x, masks)
    total = sum(terms.values())
    return jnp.where(ok, total, jnp.nan)


def _loss_key(problem: Problem) -> Problem:
    """The part of a problem the loss depends on (optimiser settings cleared): the cache key of
    :func:`_compiled`, so that runs differing only in steps or learning rate share one compile."""
    return dataclasses.replace(problem, steps=1, learning_rate=1.0, tolerance=0.0, patience=1,
                               elements_per_span=None, description="")


@functools.lru_cache(maxsize=16)
def _compiled(problem: Problem):
    """Jitted f(z, scene, rpm, masks) -> ((loss, (terms, measures)), d loss / d z), z = x / scale.

    rpm and masks are arguments, so the same compiled function also gives the frequencies
    over a Campbell grid (in chunks of len(rpm)) and takes the mode selection of "span"."""
    scales = jnp.asarray(problem.scales)

    def f(z, scene, rpm, masks):
        m = measures(scene, problem, z * scales, rpm)
        terms = terms_from_measures(m, scene, problem, masks, rpm)
        total = sum(terms.values())
        return jnp.where(m["feasible"], total, jnp.nan), (terms, m)

    return jax.jit(jax.value_and_grad(f, has_aux=True))


@functools.lru_cache(maxsize=16)
def _measures_jit(problem: Problem):
    """Jitted measures(scene, x, rpm) (no gradient): the check on a finer mesh."""
    return jax.jit(lambda scene, x, rpm: measures(scene, problem, x, rpm))


def mode_labels(scene: Scene, qi, inst, rpm: float) -> list[str] | None:
    """Labels of the modes of ``scene`` about the equilibrium (qi, inst) at drive-pulley speed
    ``rpm`` (see :func:`beltjax.drive_modal.label_modes`); None if unstable there.

    The shapes are those of (M, K) at that steady motion (centrifugal stiffness included, the
    gyroscopic coupling left out): real shapes, whose half-waves count reliably, and the same
    sorted order as the gyroscopic frequencies unless two modes nearly coincide."""
    sc = drive.canonical(scene)
    v = float(drive.belt_speed(sc, rpm))
    qi = jnp.asarray(qi)
    out = drive_modal.modes_at(sc, qi, inst, v, False)
    if not bool(out["stable"]):
        return None
    labels, _ = drive_modal.label_modes(out["freqs"], out["shapes"], qi, sc, inst, out["J"])
    return labels


def _labels_and_masks(scene: Scene, problem: Problem, m: dict) -> tuple[list, np.ndarray]:
    """Labels at each resonance objective's lowest sampled speed and the mode masks, from a
    :func:`measures` result ``m`` (numpy)."""
    rpm, labels = sample_rpm(problem), []
    for o, k in zip(_bands(problem), _band_starts(problem)):
        lab = mode_labels(scene, m["qi_speeds"][k], m["inst"], float(rpm[k]))
        if lab is None:
            raise OptimizeError(f"the drive is unstable at {rpm[k]:g} rpm",
                                f"objective[{problem.objectives.index(o)}].rpm")
        labels.append(lab)
    n = drive.n_independent(scene)
    masks = mode_masks(problem, labels, n, drive_modal.n_rigid_modes(scene))
    for j, o in enumerate(_bands(problem)):
        if not masks[j].any():
            raise OptimizeError(f"no mode is selected by modes = {o.modes!r}",
                                f"objective[{problem.objectives.index(o)}].modes")
    return labels, masks


# --------------------------------------------------------------------------- the optimiser


@dataclass
class OptimizeResult:
    """Outcome of :func:`optimise` (file units).

    paths, x0, x (best feasible values met), lower, upper; loss0, loss (total);
    terms0, terms (name -> value); measures0, measures (:func:`measures` at x0 and x, numpy,
    working mesh); labels (per resonance objective, at its lowest speed, at x0); masks (the
    mode selection); history: per accepted step {step, loss, x, learning_rate, t_s (s since the
    start)}; rejected:
    steps rejected (infeasible or non-finite) with the learning rate halved; steps: optimiser
    steps taken; converged, reason; wall_s (s, with compilation); compile_s (s, the first
    value-and-gradient call); scene: the optimised scene (the input's mesh); problem;
    working: the scene optimised on.
    """

    paths: list[str]
    x0: np.ndarray
    x: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    loss0: float
    loss: float
    terms0: dict
    terms: dict
    measures0: dict
    measures: dict
    labels: list
    masks: np.ndarray
    history: list[dict]
    rejected: int
    steps: int
    converged: bool
    reason: str
    wall_s: float
    compile_s: float
    scene: Scene = field(repr=False)
    problem: Problem = field(repr=False)
    working: Scene = field(repr=False)

    @property
    def loss_history(self) -> list[float]:
        """Total loss after each accepted step (the start first)."""
        return [h["loss"] for h in self.history]


def _floats(d: dict) -> dict:
    return {k: float(v) for k, v in d.items()}


def _decay(step: int, steps: int) -> float:
    """Cosine decay of the learning rate from 1 to 0.1 over the step budget (damps Adam's
    oscillation about a kink or an active penalty)."""
    return 0.1 + 0.45 * (1.0 + math.cos(math.pi * min(step, steps) / steps))


def optimise(scene: Scene, problem: Problem, progress: Callable[[dict], None] | None = None) -> OptimizeResult:
    """Minimise the problem's loss over its variables from the scene's values.

    Adam on x / scale, projected onto the bounds; a step whose layout is infeasible or whose
    loss or gradient is not finite is rejected and the learning rate halved (after 30
    rejections in a row the run stops).  Stops after ``problem.steps`` steps, or earlier when
    the best loss has not fallen by ``tolerance`` (relative) in ``patience`` steps or is 0.
    progress: optional callable(dict(step, steps, loss, best, learning_rate, rejected)).
    Returns the best feasible point met (never NaN).
    """
    t_start = time.perf_counter()
    work = working_scene(scene, problem)
    scales = problem.scales
    lo = np.array([v.lower for v in problem.variables]) / scales
    hi = np.array([v.upper for v in problem.variables]) / scales
    x0 = np.array([float(parameters.get_value(scene, p)) for p in problem.paths])
    vg = _compiled(_loss_key(problem))
    rpm = jnp.asarray(sample_rpm(problem))
    n = drive.n_independent(work)
    masks = jnp.ones((len(_bands(problem)), n))  # provisional: the labels need a first evaluation

    def evaluate(z):
        (val, (terms, m)), g = vg(jnp.asarray(z), work, rpm, masks)
        val, g = float(val), np.asarray(g)
        good = bool(m["feasible"]) and math.isfinite(val) and bool(np.all(np.isfinite(g)))
        return good, val, g, (_floats(terms), jax.tree.map(np.asarray, m))

    z = x0 / scales
    t0 = time.perf_counter()
    good, val, g, (terms, m0) = evaluate(z)
    compile_s = time.perf_counter() - t0
    if not bool(m0["feasible"]):
        raise OptimizeError("the starting layout is infeasible (the belt cannot be fitted, no static equilibrium, "
                            "or unstable in the speed band)", "scene")
    labels = []
    if _bands(problem):
        labels, masks_np = _labels_and_masks(work, problem, m0)
        masks = jnp.asarray(masks_np)
        good, val, g, (terms, m0) = evaluate(z)
    if not good:
        raise OptimizeError("the loss or its gradient is not finite at the starting layout", "scene")
    terms0 = terms
    opt = optax.scale_by_adam()
    state = opt.init(jnp.asarray(z))
    best = (val, z.copy(), terms, m0)
    history = [dict(step=0, loss=val, x=list(z * scales), learning_rate=problem.learning_rate,
                    t_s=time.perf_counter() - t_start)]
    lr, rejected, in_a_row, since_best, step = problem.learning_rate, 0, 0, 0, 0
    reason, converged = "step limit reached", False
    while step < problem.steps:
        if best[0] <= 0.0:
            reason, converged = "loss is 0: every objective met", True
            break
        upd, new_state = opt.update(jnp.asarray(g), state)
        rate = lr * _decay(step, problem.steps)
        z_new = np.clip(z - rate * np.asarray(upd), lo, hi)
        ok, v_new, g_new, t_new = evaluate(z_new)
        step += 1
        if not ok:
            rejected += 1
            in_a_row += 1
            lr *= 0.5
            if in_a_row >= 30:
                reason = "30 rejected steps in a row (infeasible neighbourhood)"
                break
        else:
            in_a_row = 0
            z, g, state, val = z_new, g_new, new_state, v_new
            history.append(dict(step=step, loss=val, x=list(z * scales), learning_rate=rate,
                                t_s=time.perf_counter() - t_start))
            if val < best[0] - problem.tolerance * abs(best[0]):
                since_best = 0
            else:
                since_best += 1
            if val < best[0]:
                best = (val, z.copy(), *t_new)
            if since_best >= problem.patience:
                reason = f"no relative improvement above {problem.tolerance:g} in {problem.patience} steps"
                converged = True
                break
        if progress is not None:
            progress(dict(step=step, steps=problem.steps, loss=val, best=best[0], learning_rate=rate,
                          rejected=rejected))
    x = best[1] * scales
    out_scene = parameters.set_values(scene, dict(zip(problem.paths, (float(v) for v in x))))
    return OptimizeResult(
        paths=problem.paths, x0=x0, x=x, lower=lo * scales, upper=hi * scales,
        loss0=history[0]["loss"], loss=best[0], terms0=terms0, terms=best[2], measures0=m0, measures=best[3],
        labels=labels, masks=np.asarray(masks), history=history, rejected=rejected, steps=step,
        converged=converged, reason=reason, wall_s=time.perf_counter() - t_start, compile_s=compile_s,
        scene=out_scene, problem=problem, working=work,
    )


# --------------------------------------------------------------------------- reports


def constraint_report(m: dict, scene: Scene, problem: Problem) -> list[dict]:
    """Each constraint's value, worst violation (its units) and whether it holds within its
    tolerance, from :func:`measures`-like numpy values ``m``."""
    out = []
    for j, c in enumerate(problem.constraints):
        viol, value = _violations(c, {k: np.asarray(m[k]) for k in ("wrap_deg", "tensions_N", "arm_deg", "gaps_m")},
                                  scene, np)
        worst = float(np.max(viol)) if np.size(viol) else 0.0
        value = [float(v) for v in value] if isinstance(value, tuple) else float(value)
        out.append(dict(constraint=j, kind=c.kind, where=c.where, lower=c.lower, upper=c.upper,
                        unit=_UNIT_NAME[c.kind], value=value, violation=worst, tolerance=c.tolerance,
                        satisfied=bool(worst <= c.tolerance)))
    return out


def _describe_constraint(c: dict) -> str:
    u = c["unit"]
    if c["kind"] == "min_wrap_deg":
        return f"wrap {c['where'] or 'every pulley'} >= {c['lower']:g} {u}"
    if c["kind"] == "no_overlap":
        return f"clearance between pulleys >= {c['lower']:g} {u}"
    what = "span tension" + (f" {c['where']}" if c["where"] else "") if c["kind"] == "static_tension" else "arm angle"
    lo = "" if c["lower"] is None else f"{c['lower']:g} <= "
    hi = "" if c["upper"] is None else f" <= {c['upper']:g}"
    return f"{lo}{what}{hi} {u}"


def _value_text(c: dict) -> str:
    v = c["value"]
    fmt = (lambda x: f"{x:.4g}") if c["kind"] != "no_overlap" else (lambda x: f"{x:.4f}")  # noqa: E731
    text = f"{fmt(v[0])}..{fmt(v[1])}" if isinstance(v, list) else fmt(v)
    return text + ("" if c["satisfied"] else f" (violated by {c['violation']:.3g})")


def resonance_report(rpm, freqs, labels, problem: Problem, masks) -> list[dict]:
    """Per resonance objective, from a Campbell sweep (rpm (n,), freqs (n, m) Hz, labels (m,)):
    crossings of the watched modes (``masks``, :func:`mode_masks`) with the order lines inside
    the band, the closest approach (Hz) of a watched mode to an order line in the band, and the
    largest shift still needed (Hz, exact max over the band's speeds of the sweep)."""
    from beltjax import campbell

    rpm, freqs = np.asarray(rpm, float), np.asarray(freqs, float)
    out = []
    for j, o in enumerate(_bands(problem)):
        modes = [k for k in np.flatnonzero(np.asarray(masks)[j]) if k < freqs.shape[1]]
        inside = (rpm >= o.rpm[0] - 1e-9) & (rpm <= o.rpm[1] + 1e-9)
        cx = [c for c in campbell.crossings(rpm[inside], freqs[inside], o.orders, labels)
              if c["mode"] - 1 in modes]
        F = freqs[inside][:, modes]
        g = F[None] - np.asarray(o.orders)[:, None, None] * rpm[inside][None, :, None] / 60.0
        need = band_need(F, rpm[inside], np.asarray(o.orders), o.margin_hz, soft=False)
        a = np.unravel_index(np.nanargmin(np.abs(g)), g.shape)
        out.append(dict(
            objective=problem.objectives.index(o), orders=list(o.orders), rpm=list(o.rpm), margin_hz=o.margin_hz,
            modes=[int(k) + 1 for k in modes], n_modes_checked=int(freqs.shape[1]), crossings=cx,
            clear=bool(np.nanmax(need) <= 0.0), closest_hz=float(np.abs(g[a])), closest_mode=int(modes[a[2]]) + 1,
            closest_label=labels[modes[a[2]]], closest_rpm=float(rpm[inside][a[1]]),
            max_need_hz=float(np.nanmax(need)),
        ))
    return out


def _band_grid(problem: Problem, n: int = 41) -> np.ndarray:
    """Speeds (rpm) for the before/after Campbell diagrams: 0 to 1.25 x the highest band end,
    plus a fine grid inside each band."""
    bands = _bands(problem)
    top = max(o.rpm[1] for o in bands) * 1.25
    grid = [np.linspace(0.0, top, n)] + [np.linspace(o.rpm[0], o.rpm[1], 21) for o in bands]
    return np.unique(np.round(np.concatenate(grid), 9))


def relevant_modes(problem: Problem, *freqs) -> int:
    """Number of lowest modes worth a Campbell diagram: those below 1.5 x the highest order line
    (plus margin) of any band in any of the frequency tables ``freqs`` ((speeds, modes) Hz,
    sorted per speed), plus two."""
    bands = _bands(problem)
    if not bands:
        return 0
    limit = 1.5 * max(max(o.orders) * o.rpm[1] / 60.0 + o.margin_hz for o in bands)
    return max(int(np.max(np.sum(np.asarray(F) < limit, axis=1))) for F in freqs) + 2


def _static_result(scene: Scene, m: dict) -> statics.StaticResult:
    """A :class:`beltjax.statics.StaticResult` from :func:`measures` (numpy) for reports and plots."""
    order = scene.route.order
    inst = m["inst"]
    hub = np.asarray(m["hub_N"])
    res = statics.StaticResult(
        span_names=drive.span_names(scene), span_tensions_N=np.asarray(m["tensions_N"]),
        span_lengths_m=np.asarray(m["span_lengths_m"]), belt_length_m=float(inst.belt_length),
        installation_tension_N=float(inst.tension), stretch=float(inst.stretch),
        hub_forces_N={order[i]: hub[i] for i in range(len(order))},
        wrap_angles_deg={order[i]: float(m["wrap_deg"][i]) for i in range(len(order))},
        speed_m_s=float(drive.belt_speed(scene)), tensioner_angle_deg=None, spring_moment_Nm=None,
        tensioner_pivot_force_N=None, iterations=0, qi=np.asarray(m["qi"]), q=np.asarray(m["q"]), inst=inst,
    )
    if scene.tensioner is not None:
        th = float(m["arm_deg"])
        res.tensioner_angle_deg = th
        res.spring_moment_Nm = float(drive.spring_moment(math.radians(th), scene))
        pivot = hub[order.index(TENSIONER)].copy()
        if scene.model.has("gravity"):
            t = scene.tensioner
            pivot[1] += drive.GRAVITY[1] * float(t.arm_mass + t.pulley_mass)
        res.tensioner_pivot_force_N = [float(pivot[0]), float(pivot[1])]
    return res


def check(scene: Scene, problem: Problem, evaluate: Callable, n_modes: int | None = None) -> dict:
    """Statics, Campbell diagram, constraint report and loss terms of ``scene`` (its own mesh).

    evaluate(rpm) -> :func:`measures` (numpy) of ``scene`` at speeds ``rpm`` (an array of
    len(:func:`sample_rpm`)); the Campbell grid is evaluated in chunks of that length.
    n_modes: lowest modes kept in the diagram (default 20).  The loss terms use the exact max
    over the sampled speeds.  Returns a dict: statics (StaticResult), campbell (CampbellResult
    or None), labels, masks, constraints, resonance, terms, loss.
    """
    from beltjax import campbell

    rpm = sample_rpm(problem)
    m = evaluate(rpm)
    if not bool(m["feasible"]):
        raise OptimizeError("the layout is infeasible on the scene's mesh", "scene")
    n = drive.n_independent(scene)
    cb, res, labels, masks = None, [], [], np.zeros((0, n))
    if rpm.size:
        labels, masks = _labels_and_masks(scene, problem, m)
        grid = _band_grid(problem)
        k = rpm.size
        F, good = [], []
        for s in range(0, grid.size, k):
            part = grid[s:s + k]
            mc = evaluate(np.concatenate([part, np.full(k - part.size, part[-1])]))
            F.append(np.asarray(mc["freqs_hz"])[:part.size])
            good.append(np.asarray(mc["good"])[:part.size])
        F, good = np.concatenate(F), np.concatenate(good)
        F = np.where(good[:, None], F, np.nan)
        keep = min(n, n_modes or 20)
        orders = tuple(sorted({k for o in _bands(problem) for k in o.orders}))
        cb = campbell.CampbellResult(
            rpm=grid, frequencies_hz=F[:, :keep], labels=labels[0][:keep], orders=orders,
            crossings=campbell.crossings(grid, F[:, :keep], orders, labels[0][:keep]), stable=good, converged=good,
            drive_pulley=scene.route.order[drive.drive_pulley(scene)], transport=scene.model.has("transport"),
        )
        res = resonance_report(grid, F, labels[0], problem, masks)
    terms = _floats(terms_from_measures(m, scene, problem, masks, rpm, soft=False))
    return dict(statics=_static_result(scene, m), campbell=cb, labels=labels, masks=masks,
                constraints=constraint_report(m, scene, problem), resonance=res, terms=terms,
                loss=float(sum(terms.values())))


def evaluator(scene: Scene, problem: Problem, x, result: OptimizeResult | None = None) -> Callable:
    """evaluate(rpm) -> measures (numpy) of ``scene`` at parameter values x, for :func:`check`:
    through the optimisation's compiled function when ``scene`` has the working mesh (no new
    compilation), else a forward-only compiled :func:`measures` on the scene's mesh."""
    sc = drive.canonical(scene)
    x = np.asarray(x, float)
    if result is not None and sc.model == result.working.model:
        vg = _compiled(_loss_key(problem))
        masks = jnp.asarray(result.masks)

        def evaluate(rpm):
            (_, (_, m)), _ = vg(jnp.asarray(x / problem.scales), sc, jnp.asarray(rpm, float), masks)
            return jax.tree.map(np.asarray, m)
    else:
        fn = _measures_jit(_loss_key(problem))

        def evaluate(rpm):
            return jax.tree.map(np.asarray, fn(sc, jnp.asarray(x), jnp.asarray(rpm, float)))

    return evaluate


# --------------------------------------------------------------------------- the optimised scene file


def _fmt(v: float) -> str:
    return repr(float(v))


_HEADER = re.compile(r"^\s*(\[\[?)\s*([A-Za-z0-9_.]+)\s*\]\]?\s*(#.*)?$")


def _blocks(lines: list[str]) -> list[tuple[str, int, int]]:
    """(table name, first line, end line) of each TOML table; array tables named 'pulley#<name>'."""
    heads = [(i, _HEADER.match(ln)) for i, ln in enumerate(lines)]
    heads = [(i, m) for i, m in heads if m]
    out = []
    for k, (i, m) in enumerate(heads):
        end = heads[k + 1][0] if k + 1 < len(heads) else len(lines)
        name = m.group(2)
        if m.group(1) == "[[" and name == "pulley":
            nm = next((re.match(r'^\s*name\s*=\s*"([^"]*)"', ln) for ln in lines[i + 1:end]
                       if re.match(r'^\s*name\s*=', ln)), None)
            name = f"pulley#{nm.group(1) if nm else ''}"
        out.append((name, i, end))
    return out


def _set_key(lines, block, key, component, value) -> bool:
    """Replace ``key = ...`` (or one component of ``key = [x, y]``) in ``block``; False if absent."""
    _, start, end = block
    pat = re.compile(rf"^(\s*{re.escape(key)}\s*=\s*)([^#]*?)(\s*#.*)?$")
    for i in range(start + 1, end):
        m = pat.match(lines[i])
        if not m:
            continue
        old = tomllib.loads("v = " + m.group(2))["v"]
        if component is None:
            new = _fmt(value)
        else:
            vec = list(old)
            vec[component] = float(value)
            new = "[" + ", ".join(_fmt(v) for v in vec) + "]"
        comment = m.group(3) or ""
        if "[optimised" not in comment:
            comment = (comment or "  #") + f"  [optimised; was {m.group(2).strip()}]"
        lines[i] = m.group(1) + new + comment
        return True
    return False


def edit_scene_text(text: str, scene: Scene, values: dict) -> str:
    """The scene file's text with the parameters ``values`` ({path: value}, file units) replaced.

    Keys absent from the file are inserted below their table's header; giving the belt's
    ``length`` (or ``static_tension``) comments out the other one.  Comments and layout stay.
    """
    lines = text.splitlines()
    for path, value in values.items():
        parts = path.split(".")
        component = None
        if parts[0] == "belt":
            table, key = "belt", parts[1]
        elif parts[0] == "pulley":
            table, key = f"pulley#{parts[1]}", parts[2]
            component = {"x": 0, "y": 1}[parts[3]] if len(parts) == 4 else None
        else:
            table, key = "tensioner", parts[1]
            component = {"x": 0, "y": 1}[parts[2]] if len(parts) == 3 else None
        block = next((b for b in _blocks(lines) if b[0] == table), None)
        if block is None:
            raise OptimizeError(f"no [{table.split('#')[0]}] table for {path} in the scene file", "scene")
        if key in ("length", "static_tension"):
            other = "static_tension" if key == "length" else "length"
            for i in range(block[1] + 1, block[2]):
                if re.match(rf"^\s*{other}\s*=", lines[i]):
                    lines[i] = f"# {lines[i].strip()}   (replaced by the optimised {key})"
        if not _set_key(lines, block, key, component, value):
            if component is not None:
                vec = np.asarray(parameters.get_value(scene, path.rsplit(".", 1)[0] + ".x")), \
                    np.asarray(parameters.get_value(scene, path.rsplit(".", 1)[0] + ".y"))
                vec = [float(vec[0]), float(vec[1])]
                vec[component] = float(value)
                new = f"{key} = [{_fmt(vec[0])}, {_fmt(vec[1])}]"
            else:
                new = f"{key} = {_fmt(value)}"
            lines.insert(block[1] + 1, new + "   # set by beltjax optimize")
    return "\n".join(lines) + "\n"


def _verify_scene_text(text: str, original: Scene, values: dict) -> None:
    """Raise OptimizeError unless ``text`` parses to ``original`` with exactly ``values`` changed."""
    try:
        new = loads_scene(text, source="optimized_scene.toml")
    except SceneError as exc:
        raise OptimizeError(f"the optimised scene does not parse: {exc}", "optimized_scene.toml") from None
    expected = parameters.set_values(original, values)
    for p in parameters.paths(original):
        a, b = float(parameters.get_value(new, p)), float(parameters.get_value(expected, p))
        if not ((math.isnan(a) and math.isnan(b)) or abs(a - b) <= 1e-12 * max(1.0, abs(b))):
            raise OptimizeError(f"the optimised scene file has {p} = {a!r}, expected {b!r}", "optimized_scene.toml")


# --------------------------------------------------------------------------- plots


def _plot_campbell_band(result, path, title: str, problem: Problem) -> None:
    """:func:`beltjax.plotting.plot_campbell` with each resonance objective's speed band shaded and
    its order lines drawn bold inside the band."""
    from beltjax.plotting import plot_campbell

    bands = [(o.rpm[0], o.rpm[1], tuple(o.orders),
              f"band {o.rpm[0]:g}-{o.rpm[1]:g} rpm\n"
              f"orders {', '.join(f'{k:g}x' for k in o.orders)}, margin {o.margin_hz:g} Hz")
             for o in problem.objectives if o.kind == "resonance_band"]
    plot_campbell(result, path, title=title, bands=bands)


def plot_history(result: OptimizeResult, path) -> None:
    """Save the loss history (log scale) and the variables' paths (scaled to their bounds) (PNG);
    parameter paths drawn literally, paths that lie on each other dashed with a note."""
    from beltjax.plotting import coinciding, literal, overlay_style, save, subplots

    steps = [h["step"] for h in result.history]
    fig, (a1, a2) = subplots(2, 1, figsize=(9, 6.5), sharex=True)
    a1.semilogy(steps, np.maximum(result.loss_history, 1e-12), color="tab:blue", lw=1.5)
    a1.set_ylabel("loss")
    a1.grid(alpha=0.3, which="both")
    a1.set_title(f"loss {result.loss0:.4g} -> {result.loss:.4g}; {result.steps} steps, "
                 f"{result.rejected} rejected; {result.reason}", fontsize=9)
    X = np.array([h["x"] for h in result.history])
    scaled = [(X[:, j] - result.lower[j]) / (result.upper[j] - result.lower[j]) for j in range(len(result.paths))]
    names = [literal(p, 60) for p in result.paths]
    over = coinciding(scaled)
    for j, y in enumerate(scaled):
        ls, note = overlay_style(over, names, j)
        a2.plot(steps, y, lw=1.4, ls=ls, label=names[j] + note)
    a2.set_ylim(-0.05, 1.05)
    a2.set_ylabel("(x - lower) / (upper - lower)")
    a2.set_xlabel("step")
    a2.grid(alpha=0.3)
    a2.legend(fontsize=8, loc="best")
    save(fig, path, dpi=110)


# --------------------------------------------------------------------------- the command


def _table(result: OptimizeResult, before: dict, after: dict) -> str:
    lines = [f"{'parameter':<34} {'before':>12} {'after':>12} {'change':>12}  bounds"]
    for j, p in enumerate(result.paths):
        at = " (at bound)" if result.x[j] in (result.lower[j], result.upper[j]) else ""
        lines.append(f"{p:<34} {result.x0[j]:>12.6g} {result.x[j]:>12.6g} {result.x[j] - result.x0[j]:>+12.4g}  "
                     f"[{result.lower[j]:g}, {result.upper[j]:g}]{at}")
    lines += ["", f"{'loss term (scene mesh, exact max)':<40} {'before':>12} {'after':>12}"]
    for k in before["terms"]:
        lines.append(f"{k:<40} {before['terms'][k]:>12.5g} {after['terms'][k]:>12.5g}")
    lines.append(f"{'total':<40} {before['loss']:>12.5g} {after['loss']:>12.5g}")
    if after["constraints"]:
        lines += ["", f"{'constraint':<46} {'before':>16} {'after':>16}  satisfied (tolerance)"]
        for b, a in zip(before["constraints"], after["constraints"]):
            lines.append(f"{_describe_constraint(a):<46} {_value_text(b):>16} {_value_text(a):>16}  "
                         f"{'yes' if a['satisfied'] else 'NO'} ({a['tolerance']:g} {a['unit']})")
    for b, a in zip(before["resonance"], after["resonance"]):
        shown = ", ".join(str(k) for k in a["modes"][:6]) + (", ..." if len(a["modes"]) > 6 else "")
        lines += ["", f"resonance band {a['rpm'][0]:g}-{a['rpm'][1]:g} rpm, orders "
                  f"{', '.join(f'{k:g}x' for k in a['orders'])}, margin {a['margin_hz']:g} Hz; "
                  f"{len(a['modes'])} modes watched ({shown}):"]
        for tag, r in (("before", b), ("after", a)):
            cx = "; ".join(f"mode {c['mode']} ({c['label']}) x {c['order']:g}x at {c['rpm']:.0f} rpm, "
                           f"{c['frequency_hz']:.1f} Hz" for c in r["crossings"]) or "none"
            lines.append(f"  {tag:<6} crossings in band: {cx}; closest {r['closest_hz']:.2f} Hz "
                         f"(mode {r['closest_mode']}, {r['closest_label']}, {r['closest_rpm']:.0f} rpm)"
                         + ("; clear with margin" if r["clear"] else ""))
    return "\n".join(lines)


def _statics_json(st) -> dict:
    d = st.to_json()
    keep = ("span_names", "span_tensions_N", "hub_force_magnitudes_N", "wrap_angles_deg", "belt_length_m",
            "tensioner_angle_deg", "spring_moment_Nm")
    return {k: d[k] for k in keep if k in d}


def run(scene: Scene, spec_path, out, scene_path=None) -> int:
    """The ``beltjax optimize`` command: optimise, check on the scene's mesh, write the outputs.

    Writes ``optimize.json``, ``optimized_scene.toml`` (the scene file with the variables
    replaced), ``layout_before.png`` / ``layout_after.png``, ``campbell_before.png`` /
    ``campbell_after.png`` (with a resonance objective) and ``history.png`` into ``out``;
    prints the changes, and a progress line to stderr every few steps.  Returns 0.
    """
    from beltjax.plotting import plot_layout

    from beltjax import outputs
    from beltjax.progress import Reporter, message

    t0 = time.perf_counter()
    out = pathlib.Path(out)
    problem = load(spec_path, scene)
    reporter = Reporter()  # on stderr: redrawn on a terminal, a line every few seconds elsewhere

    def progress(d):
        reporter.update(f"optimize: step {d['step']}/{d['steps']}  loss {d['loss']:.5g}  best {d['best']:.5g}  "
                        f"learning rate {d['learning_rate']:.3g}  rejected {d['rejected']}",
                        final=d["step"] == d["steps"])

    res = optimise(scene, problem, progress)
    reporter.finish()
    message("optimize: checking the start and the result on the scene's mesh")
    t_check = time.perf_counter()
    n_plot = relevant_modes(problem, res.measures0["freqs_hz"], res.measures["freqs_hz"])
    before = check(scene, problem, evaluator(scene, problem, res.x0, res), n_plot)
    after = check(res.scene, problem, evaluator(res.scene, problem, res.x, res), n_plot)
    check_s = time.perf_counter() - t_check
    changes = dict(zip(res.paths, (float(v) for v in res.x)))
    title = scene.description or str(scene_path or scene.source)
    files, note = [], None
    src = pathlib.Path(scene_path) if scene_path is not None else pathlib.Path(scene.source)
    if src.is_file():
        head = (f"# optimised by beltjax optimize ({spec_path}): "
                + ", ".join(f"{p} {a:.6g} -> {b:.6g}" for p, a, b in zip(res.paths, res.x0, res.x)) + "\n")
        text = head + edit_scene_text(textfile.read_text(src, "scene"), scene, changes)  # no byte-order mark
        _verify_scene_text(text, scene, changes)
        (out / "optimized_scene.toml").write_text(text)
        files.append("optimized_scene.toml")
    else:
        note = "optimized_scene.toml not written: the scene was not read from a file"
    for tag, chk, sc in (("before", before, scene), ("after", after, res.scene)):
        plot_layout(sc, chk["statics"], out / f"layout_{tag}.png")
        files.append(f"layout_{tag}.png")
        if chk["campbell"] is not None:
            _plot_campbell_band(chk["campbell"], out / f"campbell_{tag}.png", f"{title} ({tag} optimisation)", problem)
            files.append(f"campbell_{tag}.png")
    plot_history(res, out / "history.png")
    files.append("history.png")
    wall = time.perf_counter() - t0
    data = dict(
        scene=str(scene_path or scene.source), spec=str(spec_path), description=problem.description,
        mesh=dict(optimisation_elements_per_span=res.working.model.elements_per_span,
                  scene_elements_per_span=scene.model.elements_per_span),
        variables=[dict(parameter=p, before=float(a), after=float(b), change=float(b - a), lower=v.lower,
                        upper=v.upper, scale=v.scale)
                   for p, a, b, v in zip(res.paths, res.x0, res.x, problem.variables)],
        optimisation=dict(loss_before=res.loss0, loss_after=res.loss, terms_before=res.terms0, terms_after=res.terms,
                          constraints_before=constraint_report(res.measures0, res.working, problem),
                          constraints_after=constraint_report(res.measures, res.working, problem)),
        check=dict(loss_before=before["loss"], loss_after=after["loss"], terms_before=before["terms"],
                   terms_after=after["terms"], constraints_before=before["constraints"],
                   constraints_after=after["constraints"], resonance_before=before["resonance"],
                   resonance_after=after["resonance"], statics_before=_statics_json(before["statics"]),
                   statics_after=_statics_json(after["statics"])),
        all_constraints_satisfied=all(c["satisfied"] for c in after["constraints"]),
        steps=res.steps, rejected_steps=res.rejected, converged=res.converged, stop_reason=res.reason,
        loss_history=res.loss_history, history=res.history,
        wall_s=wall, optimisation_s=res.wall_s, first_evaluation_s=res.compile_s, check_s=check_s,
        outputs=files, note=note,
    )
    (out / "optimize.json").write_text(json.dumps(data, indent=2))
    print(f"optimised {title} with {spec_path}")
    print(f"{res.steps} steps ({res.reason}), {res.rejected} rejected; loss {res.loss0:.5g} -> {res.loss:.5g} "
          f"({res.working.model.elements_per_span} elements per span, checked with the scene's "
          f"{scene.model.elements_per_span}); wall {wall:.1f} s: optimisation {res.wall_s:.1f} s (first "
          f"evaluation with compilation {res.compile_s:.1f} s), check and plots {wall - res.wall_s:.1f} s")
    print("")
    print(_table(res, before, after))
    if note:
        print(note)
    outputs.wrote([out / f for f in ["optimize.json"] + files])
    return 0
